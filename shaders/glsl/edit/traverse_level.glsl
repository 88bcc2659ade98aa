// The traverse pass's body (edit/traverse.comp; also run for the small levels at the top of an
// edit by edit/traverse_small_levels.comp). The includer includes edit/common.glsl first.

// Min corner of child o of the cube at `corner` whose children have side `child_side`.
uvec3 child_corner(uvec3 corner, uint child_side, uint o) {
    return corner + child_side * uvec3(o & 1u, o >> 1u & 1u, o >> 2u);
}

// Traverses entries start, start + stride, ... of the `count` of the level (`push`).
void edit_traverse_level(uint start, uint stride, uint count) {
    Entries entries = Entries(push.src);
    Words nodes = Words(push.dst);
    Entries next = Entries(push.dst2);
    Words counters = Words(push.counters);
    uint tool = edit_tool();
    uint full = EDIT_FULL | push.material;
    uint child_side = 2u << push.level;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = start;
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
