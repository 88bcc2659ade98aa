// SVDAG ray traversal: the GLSL twin of `Svdag::raycast` (engine/dag/raycast.rs).
//
// The includer defines, BEFORE including this file:
//   uint dag_word(uint i);        // word i of `Svdag::words`
//   uint64_t dag_node_voxels(uint i); // `VoxelIndex::node_voxels[i]`
// Provides `struct Hit` and
//   bool trace_ray(vec3 origin, vec3 dir, float t_max, uint root_level, out Hit hit);
// `root_level` is `RenderParams::root_level` (log2(N) - 2); the grid is [0, 4 << root_level)^3.
//
// Every floating-point step performs the same f32 operations in the same order as the CPU code
// and is marked `precise` (no FMA contraction, no reassociation), so the hit decisions match the
// CPU bit for bit wherever the driver's 1/x is correctly rounded (docs/rendering.md).
#ifndef VOXDAG_RENDER_TRAVERSE_GLSL
#define VOXDAG_RENDER_TRAVERSE_GLSL

// Stack frames: depth 0 = root ... root_level = 4^3 leaf, root_level + 1 = 2^3 sub-block.
// 21 frames hold grids up to 2^21 per side, every valid .vdag (`MAX_GPU_FRAMES` /
// `MAX_GPU_RESOLUTION` in params.rs).
#define TRAVERSE_MAX_FRAMES 21u
// Inverse of a zero direction component (`PARALLEL_INV`).
#define TRAVERSE_PARALLEL_INV 1e36
// `t_max` of unbounded rays (`T_UNBOUNDED`).
#define TRAVERSE_T_UNBOUNDED 1e30

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

// Slab test of the cube [pos, pos + size]^3: near/far parameters and the axis of the near one
// (ties keep the earlier axis). The near plane of axis k is the low one unless mirror bit k is set.
void traverse_slab(TraverseRay r, uvec3 pos, uint size, out float t_near, out float t_far,
                   out uint axis) {
    precise vec3 lo = (vec3(pos) - r.origin) * r.inv;
    precise vec3 hi = (vec3(pos + uvec3(size)) - r.origin) * r.inv;
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

// 8-bit mask of the non-empty 2^3 sub-blocks of the leaf at word `ptr`.
uint traverse_leaf_block_mask(uint ptr) {
    uint lo = dag_word(ptr);
    uint hi = dag_word(ptr + 1u);
    uint mask = 0u;
    for (uint s = 0u; s < 4u; s++) {
        if (((lo >> (8u * s)) & 0xffu) != 0u) {
            mask |= 1u << s;
        }
        if (((hi >> (8u * s)) & 0xffu) != 0u) {
            mask |= 1u << (s + 4u);
        }
    }
    return mask;
}

// Byte `s` of the 64-bit mask of the leaf at word `ptr`: the voxels of sub-block s.
uint traverse_leaf_byte(uint ptr, uint s) {
    return (dag_word(ptr + (s >> 2u)) >> (8u * (s & 3u))) & 0xffu;
}

bool trace_ray(vec3 origin, vec3 dir, float t_max, uint root_level, out Hit hit) {
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
    traverse_slab(r, uvec3(0u), n, t_near, t_far, axis);
    float t_enter = max(t_near, 0.0);
    if (!(t_enter < t_far && t_enter < t_max)) {
        return false;
    }
    // Frame d: node word offset and (child mask | next ordinal << 8).
    uint stack_node[TRAVERSE_MAX_FRAMES];
    uint stack_state[TRAVERSE_MAX_FRAMES];
    stack_node[0] = 0u;
    stack_state[0] = dag_word(0u) & 0xffu;
    uint depth = 0u;
    uvec3 cursor = uvec3(0u);
    for (;;) {
        uint node = stack_node[depth];
        uint state = stack_state[depth];
        uint next = state >> 8u;
        if (next == 8u) {
            if (depth == 0u) {
                return false;
            }
            depth -= 1u;
            continue;
        }
        stack_state[depth] = state + 256u;
        uint c = next ^ r.mirror;
        if ((state & (1u << c)) == 0u) {
            continue;
        }
        uint size = n >> depth;
        uint half_size = size >> 1u;
        uvec3 child = (cursor & ~uvec3(size - 1u)) + ((uvec3(c, c >> 1u, c >> 2u) & 1u) * half_size);
        traverse_slab(r, child, half_size, t_near, t_far, axis);
        t_enter = max(t_near, 0.0);
        if (!(t_enter < t_far && t_enter < t_max)) {
            continue;
        }
        cursor = child;
        if (depth + 1u == voxel_depth) {
            hit.t = t_enter;
            hit.voxel = child;
            hit.normal = traverse_normal(dir, t_near, axis);
            // Colour index: voxels of the preceding siblings on the path, then the rank inside
            // the leaf.
            uint64_t color = 0ul;
            for (uint d = 0u; d < leaf_depth; d++) {
                uint st = stack_state[d];
                uint cd = ((st >> 8u) - 1u) ^ r.mirror;
                uint rank = uint(bitCount(st & 0xffu & ((1u << cd) - 1u)));
                for (uint k = 0u; k < rank; k++) {
                    color += dag_node_voxels(dag_word(stack_node[d] + 1u + k));
                }
            }
            uint leaf = stack_node[leaf_depth];
            uint code = ((((stack_state[leaf_depth] >> 8u) - 1u) ^ r.mirror) << 3u) |
                        (((stack_state[leaf_depth + 1u] >> 8u) - 1u) ^ r.mirror);
            uint lo = dag_word(leaf);
            if (code < 32u) {
                color += uint64_t(bitCount(lo & ((1u << code) - 1u)));
            } else {
                uint hi = dag_word(leaf + 1u);
                color += uint64_t(bitCount(lo)) + uint64_t(bitCount(hi & ((1u << (code - 32u)) - 1u)));
            }
            hit.color_index = color;
            return true;
        }
        uint child_node;
        uint child_mask;
        if (depth + 1u < leaf_depth) {
            // Inner child: follow the pointer of octant c.
            uint rank = uint(bitCount(state & 0xffu & ((1u << c) - 1u)));
            child_node = dag_word(node + 1u + rank);
            child_mask = dag_word(child_node) & 0xffu;
        } else if (depth + 1u == leaf_depth) {
            // Leaf child: its sub-block occupancy.
            uint rank = uint(bitCount(state & 0xffu & ((1u << c) - 1u)));
            child_node = dag_word(node + 1u + rank);
            child_mask = traverse_leaf_block_mask(child_node);
        } else {
            // Sub-block c of the leaf at `node`.
            child_node = node;
            child_mask = traverse_leaf_byte(node, c);
        }
        depth += 1u;
        stack_node[depth] = child_node;
        stack_state[depth] = child_mask;
    }
    return false;
}

#endif
