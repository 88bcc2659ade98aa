#version 460
// Edit, level 0: one workgroup per leaf entry, one invocation per voxel (bit = Morton code in
// the leaf). dst = temporary leaves (2 mask words each, zeroed before), src = entries.
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Entries entries = Entries(push.src);
    Words leaves = Words(push.dst);
    bool remove = (push.flags & EDIT_FLAG_REMOVE) != 0u;
    uint v = gl_LocalInvocationID.x;
    uvec3 local = uvec3(v & 1u | (v >> 2u & 2u), v >> 1u & 1u | (v >> 3u & 2u), v >> 2u & 1u | (v >> 4u & 2u));
    for (uint i = gl_WorkGroupID.x; i < push.count; i += gl_NumWorkGroups.x) {
        uvec4 e = entries.e[i];
        bool solid;
        if (edit_is_ptr(e.w)) {
            solid = (edit_read(e.w, v >> 5u) >> (v & 31u) & 1u) != 0u;
        } else {
            solid = e.w != EDIT_EMPTY;
        }
        bool inside = edit_voxel_inside(e.xyz + local);
        solid = remove ? solid && !inside : solid || inside;
        if (solid) atomicOr(leaves.w[i * 2u + (v >> 5u)], 1u << (v & 31u));
    }
}
