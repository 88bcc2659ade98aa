#version 460
// Edit, level 0: one workgroup per leaf entry, one invocation per voxel (bit = Morton code in
// the leaf): the voxel's state before the edit (from the stored leaf, or the full / empty
// value) goes through the tool (edit_new_voxel), the result is or-ed into the temporary leaf.
//   src      entries (uvec4: min corner, existing value)
//   dst      temporary leaves, zeroed before: 2 mask words, + 8 material words (nibble v =
//            material of voxel v) with EDIT_FLAG_MATERIALS
//   src2     tool parameters (EDIT_P_*), dst2 the fill's flooded bitmap
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Entries entries = Entries(push.src);
    Words leaves = Words(push.dst);
    bool materials = (push.flags & EDIT_FLAG_MATERIALS) != 0u;
    uint rec = materials ? 10u : 2u;
    uint v = gl_LocalInvocationID.x;
    uvec3 local = uvec3(v & 1u | (v >> 2u & 2u), v >> 1u & 1u | (v >> 3u & 2u), v >> 2u & 1u | (v >> 4u & 2u));
    for (uint i = gl_WorkGroupID.x; i < push.count; i += gl_NumWorkGroups.x) {
        uvec4 e = entries.e[i];
        uvec3 p = e.xyz + local;
        uint state = edit_new_voxel(p, edit_lookup(e.w, 0u, p));
        if (state == EDIT_EMPTY) continue;
        atomicOr(leaves.w[i * rec + (v >> 5u)], 1u << (v & 31u));
        if (materials) atomicOr(leaves.w[i * rec + 2u + v / 8u], state << (4u * (v % 8u)));
    }
}
