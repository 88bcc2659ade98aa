#version 460
// Load, inner level: one invocation per svdag32 node. src = svdag words, src2 = the level's
// node word offsets, dst = 8 child values per node: EDIT_EMPTY, or EDIT_TEMP | the child's
// word offset (its result is at that index of the results buffer).
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Words words = Words(push.src);
    Words offsets = Words(push.src2);
    Words out_nodes = Words(push.dst);
    uint stride = gl_NumWorkGroups.x * 64u;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) for (;;) {
        uint at = offsets.w[i];
        uint mask = words.w[at];
        uint next = at + 1u;
        for (uint o = 0u; o < 8u; ++o) {
            out_nodes.w[i * 8u + o] = (mask >> o & 1u) != 0u ? EDIT_TEMP | words.w[next++] : EDIT_EMPTY;
        }
        i += stride;
        if (i >= push.count) break;
    }
}
