// DAG ray traversal: the GLSL twin of `Svdag::raycast` (engine/dag/raycast.rs), for every DAG
// format: the format-specific child fetch is in render/dag_formats.glsl, one format per
// compiled variant (build.rs compiles every shader including this file once per format).
//
// The includer defines, BEFORE including this file (details in render/dag_formats.glsl):
//   uint dag_word(uint i);            // the DAG's words (svdag32: `Svdag::words`)
//   uint64_t dag_node_voxels(uint i); // voxel counts (svdag32: `VoxelIndex::node_voxels[i]`)
//   uint dag_info(uint i);            // format info block (unused by svdag32;
//                                     // render/dag_tables.glsl defines it from a texel buffer)
// Provides `struct Hit`,
//   void traverse_begin(uint root_level); // once per invocation, before any trace
//   bool trace_ray_indexed(..., bool want_color, out Hit hit); // colour index only if wanted
// `root_level` is `RenderParams::root_level` (log2(N) - 2); the grid is [0, 4 << root_level)^3.
//
// Every floating-point step performs the same f32 operations in the same order as the CPU code
// and is marked `precise` (no FMA contraction, no reassociation), so the hit decisions match the
// CPU bit for bit wherever the driver's 1/x is correctly rounded (docs/rendering.md).
#ifndef VOXDAG_RENDER_TRAVERSE_GLSL
#define VOXDAG_RENDER_TRAVERSE_GLSL

#extension GL_EXT_control_flow_attributes : require

// Stack frames: depth 0 = root ... root_level = 4^3 leaf, root_level + 1 = 2^3 sub-block.
// 21 frames hold grids up to 2^21 per side, every valid .vdag (`MAX_GPU_FRAMES` /
// `MAX_GPU_RESOLUTION` in params.rs).
#define TRAVERSE_MAX_FRAMES 21u
// Inverse of a zero direction component (`PARALLEL_INV`).
#define TRAVERSE_PARALLEL_INV 1e36
// `t_max` of unbounded rays (`T_UNBOUNDED`).
#define TRAVERSE_T_UNBOUNDED 1e30

#include "render/dag_formats.glsl"

// The first voxel a ray enters.
struct Hit {
    float t;          // entry parameter (origin + t * dir), >= 0
    uvec3 voxel;      // voxel coordinates
    ivec3 normal;     // entry face normal, pointing against the ray
    uint64_t color_index; // depth-first Morton index of the voxel (index into the colours)
};

// Per-ray constants of the box tests.
struct TraverseRay {
    vec3 origin;
    vec3 inv;    // 1 / dir, TRAVERSE_PARALLEL_INV for zero components
    uint mirror; // bit k set where dir[k] < 0
};

TraverseRay traverse_setup(vec3 origin, vec3 dir) {
    TraverseRay r;
    r.origin = origin;
    r.mirror = 0u;
    for (uint k = 0u; k < 3u; k++) {
        r.inv[k] = dir[k] == 0.0 ? TRAVERSE_PARALLEL_INV : 1.0 / dir[k];
        if (dir[k] < 0.0) {
            r.mirror |= 1u << k;
        }
    }
    return r;
}

// Slab test of the box [box_lo, box_hi]: near/far parameters and the axis of the near one
// (ties keep the earlier axis). The near plane of axis k is the low one unless mirror bit k is set.
void traverse_slab_box(TraverseRay r, ivec3 box_lo, ivec3 box_hi, out float t_near,
                       out float t_far, out uint axis) {
    precise vec3 lo = (vec3(box_lo) - r.origin) * r.inv;
    precise vec3 hi = (vec3(box_hi) - r.origin) * r.inv;
    vec3 near_t;
    vec3 far_t;
    for (uint k = 0u; k < 3u; k++) {
        bool m = (r.mirror & (1u << k)) != 0u;
        near_t[k] = m ? hi[k] : lo[k];
        far_t[k] = m ? lo[k] : hi[k];
    }
    if (near_t.x >= near_t.y && near_t.x >= near_t.z) {
        axis = 0u;
    } else if (near_t.y >= near_t.z) {
        axis = 1u;
    } else {
        axis = 2u;
    }
    t_near = max(max(near_t.x, near_t.y), near_t.z);
    t_far = min(min(far_t.x, far_t.y), far_t.z);
}

// The octant of the cube of side `half_size` whose corner is `cursor` inside its parent: the
// cursor's bits at that size (the cursor is aligned to it).
uint traverse_octant(uvec3 cursor, uint half_size) {
    uvec3 b = min(cursor & half_size, 1u);
    return b.x | (b.y << 1u) | (b.z << 2u);
}

// Slab test of the cube [pos, pos + size]^3.
void traverse_slab(TraverseRay r, ivec3 pos, uint size, out float t_near, out float t_far,
                   out uint axis) {
    traverse_slab_box(r, pos, pos + ivec3(size), t_near, t_far, axis);
}

// Entry face normal: the entry axis, or the dominant direction axis when the ray starts inside
// the voxel (t_near < 0); points against the ray.
ivec3 traverse_normal(vec3 dir, float t_near, uint entry_axis) {
    uint axis = entry_axis;
    if (t_near < 0.0) {
        vec3 a = abs(dir);
        if (a.x >= a.y && a.x >= a.z) {
            axis = 0u;
        } else if (a.y >= a.z) {
            axis = 1u;
        } else {
            axis = 2u;
        }
    }
    ivec3 n = ivec3(0);
    n[axis] = dir[axis] > 0.0 ? -1 : 1;
    return n;
}

#if defined(TSVDAG_TRANSLATIONS)
// A translated-subtree entry packed into one word: the translation (|t| < 16 per axis, 5 bits
// each, biased by 16) and the depth of the subtree's root frame (5 bits).
uint traverse_entry(uint depth, ivec3 shift) {
    uvec3 t = uvec3(shift + 16) & 31u;
    return t.x | (t.y << 5u) | (t.z << 10u) | (depth << 15u);
}

// The translation of a packed entry.
ivec3 traverse_entry_shift(uint e) {
    return ivec3(uvec3(e, e >> 5u, e >> 10u) & 31u) - 16;
}

// The root frame depth of a packed entry.
uint traverse_entry_depth(uint e) {
    return (e >> 15u) & 31u;
}

// The cell of a translated subtree whose root frame has side `side`, seen from `outer_base`
// (the base outside it): the cursor's cube at that size, since a subtree only changes the
// cursor's bits below its side.
ivec3 traverse_entry_cell(uvec3 cursor, uint side, ivec3 outer_base) {
    return outer_base + ivec3(cursor & ~uvec3(side - 1u));
}

// The base inside `shifts` (0..2) nested translated subtrees with entries e0 (outer) and e1
// (inner): the sum of their translations.
ivec3 traverse_translated_base(uint shifts, uint e0, uint e1) {
    ivec3 t0 = traverse_entry_shift(e0);
    return shifts == 0u ? ivec3(0) : (shifts == 1u ? t0 : t0 + traverse_entry_shift(e1));
}

// The translated-subtree state of a lane inside `shifts` (0..2) nested translated subtrees
// with entries e0 (outer) and e1 (inner), derived from the entries and the cursor: the base
// (the sum of their translations), the clip box (the intersection of their cells: the outer
// one's seen from base 0, the inner one's from the outer translation) and the root frame depth
// of the innermost (0 outside them).
void traverse_translated_state(uint shifts, uint e0, uint e1, uvec3 cursor, uint n,
                               out ivec3 base, out ivec3 clip_lo, out ivec3 clip_hi,
                               out uint shift_depth) {
    ivec3 t0 = traverse_entry_shift(e0);
    base = traverse_translated_base(shifts, e0, e1);
    uint d0 = traverse_entry_depth(e0);
    uint d1 = traverse_entry_depth(e1);
    uint s0 = n >> d0;
    uint s1 = n >> d1;
    ivec3 cell0 = traverse_entry_cell(cursor, s0, ivec3(0));
    ivec3 cell1 = traverse_entry_cell(cursor, s1, t0);
    clip_lo = shifts == 0u ? ivec3(0) : (shifts == 1u ? cell0 : max(cell0, cell1));
    clip_hi = shifts == 0u ? ivec3(n)
                           : (shifts == 1u ? cell0 + ivec3(s0)
                                           : min(cell0 + ivec3(s0), cell1 + ivec3(s1)));
    shift_depth = shifts == 0u ? 0u : (shifts == 1u ? d0 : d1);
}

// Morton code of a point inside a 16^3 cell (4 bits per axis).
uint traverse_morton16(uvec3 p) {
    uint code = 0u;
    for (uint b = 0u; b < 4u; b++) {
        code |= (((p.x >> b) & 1u) | (((p.y >> b) & 1u) << 1u) | (((p.z >> b) & 1u) << 2u)) << (3u * b);
    }
    return code;
}

// The voxels of a leaf whose coordinate along one axis is `l` (0..3): a voxel's index in the
// leaf's 64 world-order bits holds that coordinate's low bit where `low` has its bits set and
// its high bit where `high` has.
uint64_t traverse_leaf_slice(uint64_t low, uint64_t high, uint l) {
    return ((l & 1u) != 0u ? low : ~low) & ((l & 2u) != 0u ? high : ~high);
}

// Voxels of the leaf with world-order bits `bits` placed at `org` that lie in [lo, hi) and
// before Morton code `target` of the 16^3 cell starting at `cell`. Bit-sliced over the 64
// voxels (no loop over them): per axis the voxels inside the clip box and the voxels whose
// cell coordinate has each of its 4 bits set, then the 12-bit Morton code compared with
// `target` from its top bit down as 64-bit masks.
uint traverse_leaf_before(uvec2 bits, ivec3 org, ivec3 lo, ivec3 hi, ivec3 cell, uint target) {
    // Voxel index bits: x in 0 and 3, y in 1 and 4, z in 2 and 5.
    uint64_t low_bit[3] = uint64_t[3](0xAAAAAAAAAAAAAAAAul, 0xCCCCCCCCCCCCCCCCul,
                                      0xF0F0F0F0F0F0F0F0ul);
    uint64_t high_bit[3] = uint64_t[3](0xFF00FF00FF00FF00ul, 0xFFFF0000FFFF0000ul,
                                       0xFFFFFFFF00000000ul);
    uint64_t inside = ~0ul;
    // code_bit[3 b + a]: the voxels whose cell coordinate along axis a has bit b set, i.e.
    // bit 3 b + a of their Morton code (`traverse_morton16`).
    uint64_t code_bit[12];
    [[unroll]] for (uint j = 0u; j < 12u; j++) {
        code_bit[j] = 0ul;
    }
    [[unroll]] for (uint a = 0u; a < 3u; a++) {
        uint64_t in_range = 0ul;
        [[unroll]] for (uint l = 0u; l < 4u; l++) {
            uint64_t slice = traverse_leaf_slice(low_bit[a], high_bit[a], l);
            int p = org[a] + int(l);
            in_range |= p >= lo[a] && p < hi[a] ? slice : 0ul;
            uint q = uint(p - cell[a]);
            [[unroll]] for (uint b = 0u; b < 4u; b++) {
                code_bit[3u * b + a] |= ((q >> b) & 1u) != 0u ? slice : 0ul;
            }
        }
        inside &= in_range;
    }
    uint64_t before = 0ul;
    uint64_t equal = ~0ul;
    [[unroll]] for (int j = 11; j >= 0; j--) {
        uint64_t t = ((target >> uint(j)) & 1u) != 0u ? ~0ul : 0ul;
        before |= equal & t & ~code_bit[j];
        equal &= ~(code_bit[j] ^ t);
    }
    uvec2 counted = unpackUint2x32(packUint2x32(bits) & inside & before);
    return uint(bitCount(counted.x) + bitCount(counted.y));
}

// World-order rank of voxel `v` inside the translated cell [cell, cell + side) holding the
// subtree (node, xform) of `level` placed at `org` (its translation applied): the voxels of the
// subtree inside the cell with a smaller Morton code in the cell. Translated subtrees are at
// most 16^3 (level <= 2), so this walks them (nested translations clip to their own cells
// too), deciding what it can without a child fetch: the Morton order grows along every axis,
// so a child whose part of the clip box starts at or after `v`'s code holds nothing before
// it, and a child wholly inside the clip box that ends before it counts whole (its pointer's
// voxel count). Only the children around `v` are fetched, and only a level-2 subtree's
// children get a frame of their own: the two frames live in registers (an array indexed per
// lane is a loop over the lanes at every access on lavapipe).
uint traverse_shifted_rank(uint node, uint xform, uint level, ivec3 org, ivec3 cell, uint side,
                           ivec3 v) {
    uint target = traverse_morton16(uvec3(v - cell));
    ivec3 lo0 = cell;
    ivec3 hi0 = cell + ivec3(side);
    if (level == 0u) {
        return traverse_leaf_before(dag_leaf_bits(node, xform), org, lo0, hi0, cell, target);
    }
    // Frame 0: the subtree's root; frame 1: a child of a level-2 root.
    uint aux0 = dag_node_aux(node, xform, level);
    uint todo0 = dag_frame_mask(aux0, xform);
    uint node1 = 0u;
    uint xform1 = 0u;
    uint aux1 = 0u;
    uint todo1 = 0u;
    ivec3 org1 = ivec3(0);
    ivec3 lo1 = ivec3(0);
    ivec3 hi1 = ivec3(0);
    bool in1 = false;
    uint count = 0u;
    // Two loops, as in the traversal: the inner one decides children until a lane needs a
    // fetch (or is done), the outer one fetches once, so the fetch's code does not run
    // (masked) for every child decided without it. What the fetch needs follows from the frame
    // and `c` after the inner loop.
    uint c = 0u;
    for (;;) {
        bool fetch = false;
        for (;;) {
            if ((in1 ? todo1 : todo0) == 0u) {
                if (!in1) {
                    break;
                }
                in1 = false;
                continue;
            }
            uint todo = in1 ? todo1 : todo0;
            c = uint(findLSB(todo));
            todo &= todo - 1u;
            todo1 = in1 ? todo : todo1;
            todo0 = in1 ? todo0 : todo;
            ivec3 lo = in1 ? lo1 : lo0;
            ivec3 hi = in1 ? hi1 : hi0;
            int half_side = 2 << (in1 ? level - 1u : level);
            // The child's cube here (a translated child's cell, before its move): its voxels
            // lie in its part of the clip box.
            ivec3 cube = (in1 ? org1 : org) + ivec3(uvec3(c, c >> 1u, c >> 2u) & 1u) * half_side;
            ivec3 cube_last = cube + ivec3(half_side - 1);
            ivec3 part_lo = max(lo, cube);
            if (any(greaterThan(part_lo, min(hi - 1, cube_last))) ||
                traverse_morton16(uvec3(part_lo - cell)) >= target) {
                continue;
            }
            if (all(greaterThanEqual(cube, lo)) && all(lessThan(cube_last, hi)) &&
                traverse_morton16(uvec3(cube_last - cell)) < target) {
                uint f_xform = in1 ? xform1 : xform;
                uint so = xform_stored_octant(f_xform, c);
                count += uint(dag_node_voxels(dag_pointer_index(in1 ? node1 : node,
                                                                in1 ? aux1 : aux0, so)));
                continue;
            }
            fetch = true;
            break;
        }
        if (!fetch) {
            break;
        }
        uint lvl = in1 ? level - 1u : level;
        int half_side = 2 << lvl;
        ivec3 lo = in1 ? lo1 : lo0;
        ivec3 hi = in1 ? hi1 : hi0;
        ivec3 cube = (in1 ? org1 : org) + ivec3(uvec3(c, c >> 1u, c >> 2u) & 1u) * half_side;
        uint child;
        uint child_xform;
        ivec3 shift;
        uint at;
        dag_child(in1 ? node1 : node, in1 ? xform1 : xform, in1 ? aux1 : aux0, lvl, c, child,
                  child_xform, shift, at);
        ivec3 corg = cube;
        if (any(notEqual(shift, ivec3(0)))) {
            lo = max(lo, cube);
            hi = min(hi, cube + ivec3(half_side));
            corg += shift;
        }
        if (lvl == 1u) {
            count += traverse_leaf_before(dag_leaf_bits(child, child_xform), corg, lo, hi, cell,
                                          target);
        } else {
            node1 = child;
            xform1 = child_xform;
            aux1 = dag_node_aux(child, child_xform, lvl - 1u);
            todo1 = dag_frame_mask(aux1, child_xform);
            org1 = corg;
            lo1 = lo;
            hi1 = hi;
            in1 = true;
        }
    }
    return count;
}
#endif

// Per-invocation setup of the format (its constants read once into registers: every read costs
// a gather or a per-lane loop on lavapipe, so none is repeated per ray or per node).
void traverse_begin(uint root_level) {
    dag_begin(root_level);
}

// The ordinals (visit order i, child i ^ mirror) of the children in the world mask `mask`:
// bit i set when child i ^ mirror is.
uint traverse_order(uint mask, uint mirror) {
    uint m = mask;
    m = (mirror & 1u) != 0u ? ((m & 0x55u) << 1u) | ((m >> 1u) & 0x55u) : m;
    m = (mirror & 2u) != 0u ? ((m & 0x33u) << 2u) | ((m >> 2u) & 0x33u) : m;
    m = (mirror & 4u) != 0u ? ((m & 0x0fu) << 4u) | ((m >> 4u) & 0x0fu) : m;
    return m;
}

// Non-empty 2^3 sub-blocks of a 4^3 leaf (bit s: byte s of the bits is non-zero).
uint traverse_block_mask(uvec2 bits) {
    uint mask = 0u;
    for (uint s = 0u; s < 4u; s++) {
        mask |= (((bits.x >> (8u * s)) & 0xffu) != 0u ? 1u : 0u) << s;
        mask |= (((bits.y >> (8u * s)) & 0xffu) != 0u ? 1u : 0u) << (s + 4u);
    }
    return mask;
}

// The traversal visits the same children in the same order, with the same slab tests, as
// `Svdag::raycast`, so it finds the same voxel; how it is organised is shaped by lavapipe, which
// runs 8 invocations as the lanes of one SIMD loop and executes every branch of the loop body
// on every iteration (masked) while any lane is still looping (docs/pathtracing.md, "Where the
// time goes on lavapipe"):
// - the current frame lives in registers (node, transform, aux word, ordinals left to visit);
//   the stack arrays are written on a descent and read on a pop only;
// - `todo` holds the ordinals of the non-empty children left, so empty octants take no
//   iteration (the CPU steps through all 8);
// - the 64 bits of the current leaf stay in registers: sub-block masks and the leaf rank cost
//   no loads;
// - a pop and the next child's test share an iteration;
// - the child fetch (the format's costly part) is in an outer loop around the advance loop,
//   so it runs once per descent instead of on every iteration (see the loops below);
// - the colour index is computed once, after the loop (inside it, its loops and loads would run
//   masked on every iteration).
// `want_color`: compute `hit.color_index` (else it stays 0): callers whose albedo does not read
// it (no colours, a uniform albedo, shadow rays) skip its loads and, for S+A+T, the walk of the
// translated cell.
bool trace_ray_indexed(vec3 origin, vec3 dir, float t_max, uint root_level, bool want_color,
                       out Hit hit) {
    hit.t = 0.0;
    hit.voxel = uvec3(0u);
    hit.normal = ivec3(0);
    hit.color_index = 0ul;
    if (any(isnan(origin)) || any(isinf(origin)) || any(isnan(dir)) || any(isinf(dir)) ||
        all(equal(dir, vec3(0.0)))) {
        return false;
    }
    if (root_level < 1u || root_level + 2u > TRAVERSE_MAX_FRAMES) {
        return false;
    }
    uint n = 4u << root_level;
    uint leaf_depth = root_level;
    uint voxel_depth = root_level + 2u;
    TraverseRay r = traverse_setup(origin, dir);
    float t_near;
    float t_far;
    uint axis;
    traverse_slab(r, ivec3(0), n, t_near, t_far, axis);
    float t_enter = max(t_near, 0.0);
    if (!(t_enter < t_far && t_enter < t_max)) {
        return false;
    }
    // Frame d below the current one: node handle and (aux word | ordinals left when it
    // descended, the visited one included as the lowest bit, << 16 | transform id << 24).
    // The aux word is what the format's child fetch takes (svdag32: the
    // child mask; SSVDAG/TSVDAG: the node header, so a descent does not load it again); leaf
    // and sub-block frames keep their world child mask there. The frames above the leaf are
    // written by the outer loop when it follows a pointer; the leaf frame's state stays in a
    // register (`leaf_state`, its node is `node` while in its sub-blocks), so the advance loop
    // writes no stack (an array written at a per-lane index costs a loop over the lanes on
    // lavapipe, on every iteration).
    uint stack_node[TRAVERSE_MAX_FRAMES];
    uint stack_state[TRAVERSE_MAX_FRAMES];
    uint leaf_state = 0u;
    uint node;
    uint xform;
    uint aux;
    uint mask;
    dag_root_frame(root_level, node, xform, aux, mask);
    uint todo = traverse_order(mask, r.mirror);
    uint depth = 0u;
    uvec2 leaf_bits = uvec2(0u);
    // Cube of frame d: base + (cursor & ~(size_d - 1)). `base` is 0 except inside translated
    // subtrees, where it is the sum of their translations: entering one moves the base and
    // keeps the cursor, whose bits below the subtree's side then walk it from its translated
    // origin. The cursor is the cube of the last child tested, the hit voxel when `found`: what
    // the outer loop and the hit read back from it (octant, origin) is derived, not carried
    // through the loops.
    uvec3 cursor = uvec3(0u);
    bool found = false;
#if defined(TSVDAG_TRANSLATIONS)
    // The second stack: one entry per translated subtree on the path, packed (see
    // `traverse_entry`): the depth of its root frame and its translation. Voxels outside the
    // clip box (the intersection of the subtrees' cells) are dropped, as the destructive
    // translation says. The base, the clip box and the innermost root depth follow from the
    // entries and the cursor (`traverse_translated_state`). Every value live across the
    // loops costs on every iteration (spills), and an entry written by selects costs one select
    // per value, so the 8 values of two unpacked entries are 2 here. Two are enough: only
    // 16^3 and 8^3 subtrees get an entry (a translated leaf is moved in the fetch), and a
    // translated subtree nests only inside a larger one.
    uint shifts = 0u;
    uint sh_entry0 = 0u;
    uint sh_entry1 = 0u;
#else
    const ivec3 base = ivec3(0);
    const uint shift_depth = 0u;
#endif
    // Two nested loops: the inner one advances (pops, slab tests, descents into the cheap
    // sub-block levels) until a lane needs a child fetch, has found its voxel or is done (or,
    // S+A+T, leaves a translated subtree); the outer one then runs the format's child fetch
    // (or uncounts the translated subtree left) once. lavapipe runs every part of a loop body
    // on every iteration (masked), so the fetch, the format's costly part, runs once per
    // descent instead of once per iteration of the advance, and the advance only reads the
    // translated-subtree state (base, clip box, innermost root depth) the outer loop derives.
    // Values a lane sets under its own mask inside a loop are carried from iteration to
    // iteration (one masked select each, and a register or a spill), so what the outer loop
    // and the hit need is derived from `cursor` after the advance loop (docs/pathtracing.md,
    // "Fewer values carried through the loops").
    bool fetch = false;
    for (;;) {
#if defined(TSVDAG_TRANSLATIONS)
        // The base, the clip box and the root frame depth of the innermost translated subtree
        // (the advance loop stops when it would pop that frame, like the root frame's):
        // derived from the entries and the cursor once per iteration, so entering and leaving
        // a subtree only write an entry and the count, and none of these values is carried
        // from one iteration to the next.
        ivec3 base;
        ivec3 clip_lo;
        ivec3 clip_hi;
        uint shift_depth;
        traverse_translated_state(shifts, sh_entry0, sh_entry1, cursor, n, base, clip_lo, clip_hi,
                                  shift_depth);
#endif
        for (;;) {
            if (todo == 0u) {
                // Done with the root frame, or (S+A+T) leaving a translated subtree (the outer
                // loop uncounts it): one test in the loop, told apart outside it.
                if (depth == shift_depth) {
                    break;
                }
                depth -= 1u;
                bool to_leaf = depth == leaf_depth;
                node = to_leaf ? node : stack_node[depth];
                uint st = to_leaf ? leaf_state : stack_state[depth];
                aux = st & 0xffffu;
                xform = (st >> 24u) & 63u;
                // The frame keeps the ordinals it had left when it descended, the one it
                // descended into included (its lowest bit: the colour index reads it).
                uint left = (st >> 16u) & 0xffu;
                todo = left & (left - 1u);
            }
            if (todo == 0u) {
                continue;
            }
            uint i = uint(findLSB(todo));
            uint ordinals = todo;
            todo &= todo - 1u;
            uint c = i ^ r.mirror;
            uint size = n >> depth;
            uint half_size = size >> 1u;
            uvec3 child_local =
                (cursor & ~uvec3(size - 1u)) + ((uvec3(c, c >> 1u, c >> 2u) & 1u) * half_size);
            ivec3 child = base + ivec3(child_local);
            ivec3 box_lo = child;
            ivec3 box_hi = child + ivec3(half_size);
#if defined(TSVDAG_TRANSLATIONS)
            // Inside a translated subtree the ray is tested against the part of the child in
            // the clip box: a child the ray crosses only outside it holds no visible voxel.
            // Exact: a voxel lies wholly inside or outside the (cell-aligned) clip box, and a
            // box containing the hit voxel passes the slab test whenever the voxel does
            // ((x - o) * inv is monotonic in x). A child wholly outside it has an empty box,
            // which the slab test rejects by the same monotony (its near parameter on the
            // empty axis is at least its far one), so it needs no test of its own.
            // (Outside translated subtrees the clip box is the grid: no branch needed.)
            box_lo = max(box_lo, clip_lo);
            box_hi = min(box_hi, clip_hi);
#endif
            traverse_slab_box(r, box_lo, box_hi, t_near, t_far, axis);
            t_enter = max(t_near, 0.0);
            if (!(t_enter < t_far && t_enter < t_max)) {
                continue;
            }
            cursor = child_local;
            if (depth + 1u == voxel_depth) {
                found = true;
                break;
            }
            if (depth + 1u <= leaf_depth) {
                // Inner or leaf child: its pointer is followed by the outer loop.
                fetch = true;
                break;
            }
            // Sub-block c of the leaf in leaf_bits.
            leaf_state = aux | (ordinals << 16u) | (xform << 24u);
            uint block = (((c & 4u) != 0u ? leaf_bits.y : leaf_bits.x) >> (8u * (c & 3u))) & 0xffu;
            depth += 1u;
            aux = block;
            todo = traverse_order(block, r.mirror);
        }
        if (!fetch) {
#if defined(TSVDAG_TRANSLATIONS)
            if (!found && depth != 0u) {
                // Leaving a translated subtree, back to the frame that holds its root (the
                // inner loop then pops that frame as usual).
                shifts -= 1u;
                continue;
            }
#endif
            break;
        }
        fetch = false;
        // Follow the pointer of world octant fetch_c of the frame at `depth`: the child's cube
        // is the cursor's, its octant the cursor's bits at the child's size.
        uint fetch_c = traverse_octant(cursor, n >> (depth + 1u));
        // The frame's ordinals left when it descended: the ones still to visit and the
        // visited one, below them.
        stack_node[depth] = node;
        stack_state[depth] = aux | ((todo | (1u << (fetch_c ^ r.mirror))) << 16u) | (xform << 24u);
        uint child_node = node;
        uint child_xform = xform;
        uint child_mask;
        uint child_aux;
        ivec3 shift = ivec3(0);
        uint at;
        uint level = root_level - depth;
        dag_child(node, xform, aux, level, fetch_c, child_node, child_xform, shift, at);
        uvec2 bits;
        dag_child_masks(child_node, child_xform, level - 1u, child_mask, bits, child_aux);
        if (depth + 1u == leaf_depth) {
#if defined(TSVDAG_TRANSLATIONS)
            // A translated leaf is moved in its cell here, so it needs no frames of its own
            // (docs/pathtracing.md, "Translated leaves moved in the fetch").
            bits = xform_leaf_shift(bits, shift);
#endif
            leaf_bits = bits;
            child_mask = traverse_block_mask(bits);
            child_aux = child_mask;
        }
        depth += 1u;
        node = child_node;
        xform = child_xform;
        aux = child_aux;
        todo = traverse_order(child_mask, r.mirror);
#if defined(TSVDAG_TRANSLATIONS)
        if (any(notEqual(shift, ivec3(0))) && depth != leaf_depth) {
            // Enter a translated subtree: its frames start at its translated origin (the base
            // moves, the cursor stays); only the voxels inside the cell (and any outer
            // translated cell) count.
            uint entry = traverse_entry(depth, shift);
            sh_entry0 = shifts == 0u ? entry : sh_entry0;
            sh_entry1 = shifts == 1u ? entry : sh_entry1;
            shifts += 1u;
        }
#endif
    }
    if (!found) {
        return false;
    }
    // The hit voxel is the cursor's cube; its slab test again, on the same values, gives the
    // same entry (inside a translated subtree the clipped box of a hit voxel is the voxel).
#if defined(TSVDAG_TRANSLATIONS)
    ivec3 hit_voxel = traverse_translated_base(shifts, sh_entry0, sh_entry1) + ivec3(cursor);
#else
    ivec3 hit_voxel = ivec3(cursor);
#endif
    uint hit_c = traverse_octant(cursor, 1u);
    float hit_t_near;
    uint hit_axis;
    traverse_slab(r, hit_voxel, 1u, hit_t_near, t_far, hit_axis);
    hit.t = max(hit_t_near, 0.0);
    hit.voxel = uvec3(hit_voxel);
    hit.normal = traverse_normal(dir, hit_t_near, hit_axis);
    if (!want_color) {
        return true;
    }
    // Colour index: voxels of the preceding siblings (world order) on the path, then the rank
    // inside the leaf (or inside the outermost translated subtree).
    uint64_t color = 0ul;
    uint ranked_depth = leaf_depth;
#if defined(TSVDAG_TRANSLATIONS)
    if (shifts > 0u) {
        ranked_depth = traverse_entry_depth(sh_entry0);
    }
#endif
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint d = 0u;
    if (d < ranked_depth) for (;;) {
        uint st = stack_state[d];
        uint cd = uint(findLSB((st >> 16u) & 0xffu)) ^ r.mirror;
        color += dag_voxels_before(stack_node[d], (st >> 24u) & 63u, st & 0xffffu, root_level - d,
                                   cd);
        d += 1u;
        if (d >= ranked_depth) break;
    }
#if defined(TSVDAG_TRANSLATIONS)
    if (shifts > 0u) {
        // The siblings before the translated cell are counted; add the voxel's rank among the
        // voxels the translated subtree leaves in its cell.
        uint d0 = traverse_entry_depth(sh_entry0);
        uint side = n >> d0;
        ivec3 cell0 = traverse_entry_cell(cursor, side, ivec3(0));
        ivec3 origin0 = cell0 + traverse_entry_shift(sh_entry0);
        // (A translated leaf's frame is the leaf frame, kept in registers.)
        bool leaf0 = d0 == leaf_depth;
        uint node0 = leaf0 ? node : stack_node[d0];
        uint state0 = leaf0 ? leaf_state : stack_state[d0];
        color += uint64_t(traverse_shifted_rank(node0, (state0 >> 24u) & 63u, root_level - d0,
                                                origin0, cell0, side, hit_voxel));
        hit.color_index = color;
        return true;
    }
#endif
    // Rank inside the leaf (the hit's frame is one of its sub-blocks, so `node` is the leaf):
    // its voxels before Morton code (sub-block << 3 | voxel).
    uint code = ((uint(findLSB((leaf_state >> 16u) & 0xffu)) ^ r.mirror) << 3u) | hit_c;
#if defined(DAG_HAS_LEAF_RANK)
    // The format's own index inside the leaf (hash DAG: the voxel's material).
    uint rank = dag_leaf_rank(node, (leaf_state >> 24u) & 63u, code);
#else
    uint rank = code < 32u ? uint(bitCount(leaf_bits.x & ((1u << code) - 1u)))
                           : uint(bitCount(leaf_bits.x)) +
                                 uint(bitCount(leaf_bits.y & ((1u << (code - 32u)) - 1u)));
#endif
    hit.color_index = color + uint64_t(rank);
    return true;
}

#endif
