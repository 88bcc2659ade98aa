#version 460
// Edit, top-down, one invocation per node of an inner level inside the tool's reach
// (push.level >= 1). Per child the tool (edit_tool(), push.material, region push.shape /
// push.tool) decides: keep the existing child when no voxel of it can change (outside the
// region, or a homogeneous child the tool cannot change: full of the added / painted material,
// empty under remove / paint, full under fill / copy, which only fill empty voxels); fill
// (EDIT_FULL | material) or clear (EDIT_EMPTY) when add / remove / paint covers every voxel
// (paint only of a uniform child: it keeps the geometry); else subdivide (append the child to
// the next level's entries).
//   src      entries (uvec4: min corner xyz in voxels, the existing value there)
//   dst      temporary nodes (8 child values; EDIT_TEMP | j names next entry j)
//   dst2     next level's entries; counters[0..4] = their count and the indirect dispatch
//            arguments of the next level's pass (x = its workgroups of 64, y = z = 1: the host
//            sets them to 1), so that the levels can be recorded into one submission
//   count_at this level's count (counters of the level above) when recorded that way
#include "edit/common.glsl"
layout(local_size_x = 64) in;

// Min corner of child o of the cube at `corner` whose children have side `child_side`.
uvec3 child_corner(uvec3 corner, uint child_side, uint o) {
    return corner + child_side * uvec3(o & 1u, o >> 1u & 1u, o >> 2u);
}

void main() {
    Entries entries = Entries(push.src);
    Words nodes = Words(push.dst);
    Entries next = Entries(push.dst2);
    Words counters = Words(push.counters);
    uint tool = edit_tool();
    uint full = EDIT_FULL | push.material;
    uint child_side = 2u << push.level;
    uint stride = gl_NumWorkGroups.x * 64u;
    uint count = edit_count();
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < count) for (;;) {
        uvec4 e = entries.e[i];
        uint children[8];
        edit_children(e.w, children);
        // Decide every child first; the subdivided ones then take consecutive entries of the
        // next level with one atomicAdd (atomics are a loop over the lanes on lavapipe).
        uint values[8];
        uint subdivide = 0u;
        for (uint o = 0u; o < 8u; ++o) {
            uvec3 p = child_corner(e.xyz, child_side, o);
            uint c = children[o];
            bool keep;
            if (tool == EDIT_TOOL_ADD) {
                keep = c == full;
            } else if (tool == EDIT_TOOL_REMOVE) {
                keep = c == EDIT_EMPTY;
            } else if (tool == EDIT_TOOL_PAINT) {
                keep = c == EDIT_EMPTY || c == full;
            } else {
                keep = edit_is_full(c);
            }
            values[o] = c;
            if (keep || edit_cube_all_outside(p, child_side)) {
                continue;
            }
            if (tool <= EDIT_TOOL_PAINT && (tool != EDIT_TOOL_PAINT || !edit_is_ptr(c))
                && edit_cube_all_inside(p, child_side)) {
                values[o] = tool == EDIT_TOOL_REMOVE ? EDIT_EMPTY : full;
            } else {
                subdivide |= 1u << o;
            }
        }
        uint n = uint(bitCount(subdivide));
        uint first = n != 0u ? atomicAdd(counters.w[0], n) : 0u;
        for (uint o = 0u; o < 8u; ++o) {
            if ((subdivide >> o & 1u) != 0u) {
                uint j = first + uint(bitCount(subdivide & ((1u << o) - 1u)));
                if (j < push.capacity) {
                    next.e[j] = uvec4(child_corner(e.xyz, child_side, o), children[o]);
                }
                values[o] = EDIT_TEMP | j;
            }
            nodes.w[i * 8u + o] = values[o];
        }
        if (n != 0u && first < push.capacity) {
            // The next level's workgroups: up to its last entry written.
            uint last = min(first + n, push.capacity) - 1u;
            atomicMax(counters.w[1], min(last / 64u + 1u, 65535u));
        }
        i += stride;
        if (i >= count) break;
    }
}
