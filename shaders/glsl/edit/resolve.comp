#version 460
// After the level's inserts: every EDIT_PENDING result becomes the NodePtr of its item's
// representative. dst = results, dst2 = result index (EDIT_FLAG_RESULT_INDEX),
// tables = the level's address buffer, whose missing counter counts items left without a
// handle (their results stay EDIT_PENDING, so that the pass can run again once a later insert
// round placed them).
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Words results = Words(push.dst);
    Addresses tables = Addresses(push.tables);
    Words slots = Words(tables.a[EDIT_LEVEL_SLOTS]);
    EditLevelHandles level = edit_level_handles(tables);
    uint stride = gl_NumWorkGroups.x * 64u;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) for (;;) {
        uint at = (push.flags & EDIT_FLAG_RESULT_INDEX) != 0u ? Words(push.dst2).w[i] : i;
        uint r = results.w[at];
        if ((r & EDIT_TAG_MASK) == EDIT_PENDING) {
            uint v = edit_resolve_slot(level, slots.w[i], r);
            if (v == r) {
                atomicAdd(Words(tables.a[EDIT_LEVEL_MISSING]).w[0], 1u);
            }
            results.w[at] = v;
        }
        i += stride;
        if (i >= push.count) break;
    }
}
