#version 460
// Before the insert rounds of a level, every size in one pass: items that are not their dedup
// representative and were not found get HASH_INVALID, so only one copy of each new item is
// inserted. Sizes with fewer than two items are skipped (a single item is its own
// representative).
//   tables   the level's buffer addresses (EDIT_LEVEL_REPS: smallest equal index per item,
//            EDIT_LEVEL_HANDLES, EDIT_LEVEL_STRIDE)
//   counters the level's 9 per-size item counts (build_items)
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Addresses tables = Addresses(push.tables);
    Words counters = Words(push.counters);
    EditLevelHandles level = edit_level_handles(tables);
    uint stride = gl_NumWorkGroups.x * 64u;
    for (uint s = 0u; s < 9u; ++s) {
        uint n = counters.w[s];
        if (n < 2u) continue;
        uint64_t base = 4ul * uint64_t(s * level.stride);
        Words reps = Words(level.reps + base);
        Words handles = Words(level.handles + base);
        // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
        uint i = gl_GlobalInvocationID.x;
        if (i < n) for (;;) {
            if (reps.w[i] != i && handles.w[i] == HASH_MISS) handles.w[i] = HASH_INVALID;
            i += stride;
            if (i >= n) break;
        }
    }
}
