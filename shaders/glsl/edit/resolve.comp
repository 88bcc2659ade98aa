#version 460
// After the level's inserts: every EDIT_PENDING result becomes the NodePtr of its item's
// representative. dst = results, dst2 = result index (EDIT_FLAG_RESULT_INDEX),
// tables = the level's address buffer, counters[0] counts items left without a handle (their
// results stay EDIT_PENDING, so that the pass can run again once a later insert round placed
// them).
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Words results = Words(push.dst);
    Addresses tables = Addresses(push.tables);
    uint stride = gl_NumWorkGroups.x * 64u;
    for (uint i = gl_GlobalInvocationID.x; i < push.count; i += stride) {
        uint at = (push.flags & EDIT_FLAG_RESULT_INDEX) != 0u ? Words(push.dst2).w[i] : i;
        uint r = results.w[at];
        if ((r & EDIT_TAG_MASK) != EDIT_PENDING) continue;
        uint s = r & 15u;
        uint index = Words(tables.a[EDIT_LEVEL_SLOTS]).w[i];
        uint rep = Words(tables.a[EDIT_LEVEL_REPS + s]).w[index];
        uint handle = Words(tables.a[EDIT_LEVEL_HANDLES + s]).w[rep];
        if (handle >= (1u << 28u)) {
            atomicAdd(Words(push.counters).w[0], 1u);
            continue;
        }
        results.w[at] = s << 28u | handle;
    }
}
