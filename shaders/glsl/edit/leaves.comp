#version 460
// Edit, level 0: one invocation per leaf entry, looping over its 64 voxels (bit = Morton code in
// the leaf): the voxel's state before the edit (from the stored leaf, read once, or the full /
// empty value) goes through the tool (edit_new_voxel); the new masks and materials are built in
// registers and written once. (One invocation per voxel with atomicOr cost lavapipe, which runs
// each workgroup as a task on the CPU, ~20 us per leaf.)
//   src      entries (uvec4: min corner, existing value)
//   dst      temporary leaves, every word written: 2 mask words, + 8 material words (nibble v =
//            material of voxel v) with materials (edit_materials())
//   src2     tool parameters (EDIT_P_*), dst2 the fill's flooded bitmap
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Entries entries = Entries(push.src);
    Words leaves = Words(push.dst);
    bool materials = edit_materials();
    uint rec = materials ? 10u : 2u;
    uint stride = gl_NumWorkGroups.x * 64u;
    uint count = edit_count();
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < count) for (;;) {
        uvec4 e = entries.e[i];
        bool stored = edit_is_ptr(e.w);
        // The stored leaf (edit_lookup at level 0), found and its masks read once for the 64
        // voxels.
        EditItem old_leaf;
        uint old_lo = 0u;
        uint old_hi = 0u;
        if (stored) {
            old_leaf = edit_item(e.w);
            old_lo = edit_item_read(old_leaf, 0u);
            old_hi = edit_item_read(old_leaf, 1u);
        }
        uint lo = 0u;
        uint hi = 0u;
        // Left to the compiler (Mesa unrolls the inner loop): unrolled by hand, the 64 voxels'
        // code took lavapipe ~40 ms more to compile, on the first edit with each tool.
        for (uint w = 0u; w < 8u; ++w) {
            uint mats = 0u;
            for (uint k = 0u; k < 8u; ++k) {
                uint v = w * 8u + k;
                uvec3 local = uvec3(v & 1u | (v >> 2u & 2u), v >> 1u & 1u | (v >> 3u & 2u), v >> 2u & 1u | (v >> 4u & 2u));
                uint old;
                if (!stored) {
                    old = e.w == EDIT_EMPTY ? EDIT_EMPTY : e.w & 15u;
                } else if (((v < 32u ? old_lo >> v : old_hi >> (v - 32u)) & 1u) == 0u) {
                    old = EDIT_EMPTY;
                } else if (!materials) {
                    old = 0u;
                } else {
                    // Materials are packed by rank among the set bits (item.rs `Leaf`).
                    uint rank = v < 32u ? bitCount(old_lo & ((1u << v) - 1u))
                                        : bitCount(old_lo) + bitCount(old_hi & ((1u << (v - 32u)) - 1u));
                    old = edit_item_read(old_leaf, 2u + rank / 8u) >> (4u * (rank % 8u)) & 15u;
                }
                uint state = edit_new_voxel(e.xyz + local, old);
                if (state != EDIT_EMPTY) {
                    if (v < 32u) {
                        lo |= 1u << v;
                    } else {
                        hi |= 1u << (v - 32u);
                    }
                    mats |= state << (4u * k);
                }
            }
            if (materials) leaves.w[i * rec + 2u + w] = mats;
        }
        leaves.w[i * rec] = lo;
        leaves.w[i * rec + 1u] = hi;
        i += stride;
        if (i >= count) break;
    }
}
