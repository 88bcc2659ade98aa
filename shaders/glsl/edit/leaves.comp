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
        // The stored leaf's material words (as many as it has), read once for its 64 voxels: a
        // read at a per-lane address is a loop over the lanes on lavapipe, which the 64 voxels'
        // reads of their own words each ran.
        uvec4 mats_lo = uvec4(0u);
        uvec4 mats_hi = uvec4(0u);
        if (stored) {
            old_leaf = edit_item(e.w);
            old_lo = edit_item_read(old_leaf, 0u);
            old_hi = edit_item_read(old_leaf, 1u);
            if (materials) {
                [[unroll]] for (uint k = 0u; k < 4u; ++k) {
                    if (2u + k < old_leaf.words) mats_lo[k] = edit_item_read(old_leaf, 2u + k);
                    if (6u + k < old_leaf.words) mats_hi[k] = edit_item_read(old_leaf, 6u + k);
                }
            }
        }
        uint lo = 0u;
        uint hi = 0u;
        // Voxel v = 8 w + k: its coordinates' low bits are k's, their high bits w's. The eight
        // voxels of a w are unrolled (their coordinates, bits and shifts then constants or
        // uniform; left to Mesa, the loop stayed a loop of ~385 instructions per voxel on
        // lavapipe), the eight w are not (unrolling all 64 cost ~40 ms more compile per tool).
        // `rank` counts the stored leaf's voxels before v, the index of v's material.
        uint rank = 0u;
        for (uint w = 0u; w < 8u; ++w) {
            uint old_bits = leaf_byte(old_lo, old_hi, w);
            uvec3 high = uvec3(w & 1u, w >> 1u & 1u, w >> 2u & 1u) << 1u;
            uint new_bits = 0u;
            uint mats = 0u;
            [[unroll]] for (uint k = 0u; k < 8u; ++k) {
                uvec3 local = high | uvec3(k & 1u, k >> 1u & 1u, k >> 2u & 1u);
                bool was_set = (old_bits >> k & 1u) != 0u;
                uint old;
                if (!stored) {
                    old = e.w == EDIT_EMPTY ? EDIT_EMPTY : e.w & 15u;
                } else if (!was_set) {
                    old = EDIT_EMPTY;
                } else if (!materials) {
                    old = 0u;
                } else {
                    // Materials are packed by rank among the set bits (item.rs `Leaf`).
                    uint r = rank / 8u;
                    uvec4 quad = r < 4u ? mats_lo : mats_hi;
                    uint word = (r & 2u) != 0u ? ((r & 1u) != 0u ? quad.w : quad.z)
                                                : ((r & 1u) != 0u ? quad.y : quad.x);
                    old = word >> (4u * (rank % 8u)) & 15u;
                }
                rank += was_set ? 1u : 0u;
                uint state = edit_new_voxel(e.xyz + local, old);
                if (state != EDIT_EMPTY) {
                    new_bits |= 1u << k;
                    mats |= state << (4u * k);
                }
            }
            if (w < 4u) {
                lo |= new_bits << (8u * w);
            } else {
                hi |= new_bits << (8u * (w - 4u));
            }
            if (materials) leaves.w[i * rec + 2u + w] = mats;
        }
        leaves.w[i * rec] = lo;
        leaves.w[i * rec + 1u] = hi;
        i += stride;
        if (i >= count) break;
    }
}
