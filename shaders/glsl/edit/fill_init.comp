#version 460
// Fill, before the flood: one invocation per voxel of the fill box (x fastest). A voxel is
// free when it is inside the fill cube (push.tool) and empty in the pre-edit root (push.root);
// the start voxel (params[EDIT_P_START]) is flooded whatever its state (tool.rs `FillSet`).
//   src2     tool parameters (EDIT_P_*)
//   dst      free bitmap, dst2 flooded bitmap (both zeroed before)
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    uvec3 lo = uvec3(edit_param(EDIT_P_MIN), edit_param(EDIT_P_MIN + 1u), edit_param(EDIT_P_MIN + 2u));
    uvec3 dims = uvec3(edit_param(EDIT_P_DIMS), edit_param(EDIT_P_DIMS + 1u), edit_param(EDIT_P_DIMS + 2u));
    uint start = edit_param(EDIT_P_START);
    uint root_level = edit_param(EDIT_P_ROOT_LEVEL);
    uint stride = gl_NumWorkGroups.x * 64u;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) for (;;) {
        uvec3 p = lo + uvec3(i % dims.x, i / dims.x % dims.y, i / dims.x / dims.y);
        if (edit_voxel_inside(p) && edit_lookup(push.root, root_level, p) == EDIT_EMPTY) {
            atomicOr(Words(push.dst).w[i >> 5u], 1u << (i & 31u));
        }
        if (i == start) atomicOr(Words(push.dst2).w[i >> 5u], 1u << (i & 31u));
        i += stride;
        if (i >= push.count) break;
    }
}
