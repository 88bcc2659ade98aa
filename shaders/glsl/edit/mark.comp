#version 460
// Before the insert round of one size's batch: items that are not their dedup representative
// and were not found get HASH_INVALID, so only one copy of each new item is inserted.
//   src = representatives (smallest equal index), dst = handles.
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Words reps = Words(push.src);
    Words handles = Words(push.dst);
    uint stride = gl_NumWorkGroups.x * 64u;
    for (uint i = gl_GlobalInvocationID.x; i < push.count; i += stride) {
        if (reps.w[i] != i && handles.w[i] == HASH_MISS) handles.w[i] = HASH_INVALID;
    }
}
