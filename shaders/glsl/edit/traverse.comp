#version 460
// Edit, top-down, one invocation per node of an inner level inside the tool's reach
// (push.level >= 1): the tool decides per child: fill (EDIT_FULL | 0) or clear (EDIT_EMPTY) when
// every voxel is inside, keep the existing child when none can be, keep a homogeneous child the
// tool cannot change, else subdivide (append the child to the next level's entries).
//   src      entries (uvec4: min corner xyz in voxels, the existing value there)
//   dst      temporary nodes (8 child values; EDIT_TEMP | j names next entry j)
//   dst2     next level's entries; counters[0] = their count
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Entries entries = Entries(push.src);
    Words nodes = Words(push.dst);
    Entries next = Entries(push.dst2);
    Words counters = Words(push.counters);
    bool remove = (push.flags & EDIT_FLAG_REMOVE) != 0u;
    uint child_side = 2u << push.level;
    uint stride = gl_NumWorkGroups.x * 64u;
    for (uint i = gl_GlobalInvocationID.x; i < push.count; i += stride) {
        uvec4 e = entries.e[i];
        uint children[8];
        edit_children(e.w, children);
        for (uint o = 0u; o < 8u; ++o) {
            uvec3 p = e.xyz + child_side * uvec3(o & 1u, o >> 1u & 1u, o >> 2u);
            uint c = children[o];
            uint value = c;
            if (edit_cube_all_inside(p, child_side)) {
                value = remove ? EDIT_EMPTY : EDIT_FULL;
            } else if (edit_cube_all_outside(p, child_side)) {
                value = c;
            } else if (remove ? c == EDIT_EMPTY : edit_is_full(c)) {
                value = c;
            } else {
                uint j = atomicAdd(counters.w[0], 1u);
                if (j < push.capacity) next.e[j] = uvec4(p, c);
                value = EDIT_TEMP | j;
            }
            nodes.w[i * 8u + o] = value;
        }
    }
}
