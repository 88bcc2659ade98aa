#version 460
// Bottom-up, one invocation per temporary node or leaf of a level: its canonical form
// (engine/edit/item.rs). Nodes whose children are all one empty or full value become EDIT_EMPTY / EDIT_FULL | m in the results; the
// others append their item to the buffer of its size and leave EDIT_PENDING | size index.
//   src      temporary nodes (8 child values) or leaves (2 mask words, + 8 material words
//            with materials (edit_materials()): nibble v = material of voxel v); word
//            push.first of the input view
//   src2     the level below's results (EDIT_TEMP | i children read entry i; pending ones
//            are resolved here when the address buffer names the level below's, as in
//            resolve.comp, whose pass the recorded merge leaves out)
//   dst      results (one per node; at result_index[i] with EDIT_FLAG_RESULT_INDEX)
//   dst2     result_index (u32 per node)
//   tables   the level's buffer addresses (EDIT_LEVEL_* in edit/common.glsl)
//   counters 9 per-size item counts
//
// Shaped by lavapipe (docs/editing-gpu.md, "Speed, round 8" and "round 10"): every load or
// store through a buffer address is a loop over the SIMD lanes, run for every child slot
// whether or not a lane needs it, and an array indexed by a per-lane value is another such
// loop. So the reads go through word views (texel fetches, gathered for all lanes), the child
// loops are unrolled (constant indices), the addresses every node shares are read once per
// invocation, and an item's words go straight from registers to its size's buffer (no array
// of them).
#include "edit/common.glsl"
layout(local_size_x = 64) in;

// Whether the reads go through the word views below (1) or through addresses (0: a buffer has
// more words than a view takes; engine/edit/gpu/build_items.rs).
layout(constant_id = 2) const uint EDIT_SPEC_TEXELS = 1u;

// lavapipe fetches a texel for all SIMD lanes at once, where a load through a buffer address
// is a loop over them (docs/editing-gpu.md, "Speed, round 10"): the input (word push.first on
// is src's first), the level below's results (src2), and the slots, representatives and
// handles of the level whose pending results this pass resolves.
layout(set = 0, binding = 0) uniform usamplerBuffer input_texels;
layout(set = 0, binding = 1) uniform usamplerBuffer below_results_texels;
layout(set = 0, binding = 2) uniform usamplerBuffer below_slots_texels;
layout(set = 0, binding = 3) uniform usamplerBuffer below_reps_texels;
layout(set = 0, binding = 4) uniform usamplerBuffer below_handles_texels;

// A node's child values two at a time (one 64-bit load is one loop over the lanes, a uvec2 two).
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer WordPairs {
    uint64_t p[];
};

uint texel_word(usamplerBuffer t, uint i) {
    return texelFetch(t, int(i)).x;
}

// Word i of the input.
uint input_word(uint i) {
    if (EDIT_SPEC_TEXELS != 0u) return texel_word(input_texels, push.first + i);
    return Words(push.src).w[i];
}

// Words 2k and 2k + 1 of the input.
uvec2 input_pair(uint k) {
    if (EDIT_SPEC_TEXELS != 0u) return uvec2(input_word(2u * k), input_word(2u * k + 1u));
    return unpackUint2x32(WordPairs(push.src).p[k]);
}

// Entry j of the level below's results.
uint below_result(uint j) {
    if (EDIT_SPEC_TEXELS != 0u) return texel_word(below_results_texels, j);
    return Words(push.src2).w[j];
}

// The NodePtr of the level below's pending result r of node j (edit_resolve_slot through the
// views), or r where its item has no handle.
uint below_resolve(EditLevelHandles level, Words slots, uint j, uint r) {
    if (EDIT_SPEC_TEXELS == 0u) return edit_resolve_slot(level, slots.w[j], r);
    uint base = (r & 15u) * level.stride;
    uint rep = texel_word(below_reps_texels, base + texel_word(below_slots_texels, j));
    return edit_resolved(r, texel_word(below_handles_texels, base + rep));
}

// Leaf voxels 8g..8g+7 (a 2^3 sub-block) of the masks lo (voxels 0-31) and hi (32-63).
uint leaf_byte(uint lo, uint hi, uint g) {
    return ((g < 4u ? lo : hi) >> (8u * (g & 3u))) & 0xffu;
}

void main() {
    Words results = Words(push.dst);
    Addresses tables = Addresses(push.tables);
    Words counters = Words(push.counters);
    bool leaves = (push.flags & EDIT_FLAG_LEAVES) != 0u;
    bool materials = edit_materials();
    // Read once, and outside any `if` (lavapipe loads a uniform address once only there):
    // where the level below's pending results resolve (0: already resolved, and the reads
    // below come from this level's own buffer, unused) and this level's slot per node.
    uint64_t below_level = tables.a[EDIT_LEVEL_BELOW];
    uint64_t own_level = push.tables;
    Addresses below_tables = Addresses(below_level != 0ul ? below_level : own_level);
    Words below_slots = Words(below_tables.a[EDIT_LEVEL_SLOTS]);
    EditLevelHandles below_handles = edit_level_handles(below_tables);
    Words slots = Words(tables.a[EDIT_LEVEL_SLOTS]);
    uint missing = 0u;
    uint stride = gl_NumWorkGroups.x * 64u;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) for (;;) {
        uint c[8];
        uint lo = 0u;
        uint hi = 0u;
        uint words = 0u;
        uint result = EDIT_EMPTY;
        bool decided = false;
        // With materials: the leaf's 8 material words (nibble v = voxel v's material).
        uint mats[8];
        if (leaves) {
            uint rec = materials ? 10u : 2u;
            lo = input_word(i * rec);
            hi = input_word(i * rec + 1u);
            words = 2u;
            bool one_material = true;
            uint first = 0u;
            if (materials) {
                [[unroll]] for (uint g = 0u; g < 8u; ++g) {
                    mats[g] = input_word(i * rec + 2u + g);
                }
                first = mats[0] & 15u;
                // The set voxels whose material differs from voxel 0's: a nibble-wise compare.
                uint differ = 0u;
                [[unroll]] for (uint g = 0u; g < 8u; ++g) {
                    uint x = mats[g] ^ (first * 0x11111111u);
                    x = (x | (x >> 1u)) & 0x55555555u;
                    x = (x | (x >> 2u)) & 0x11111111u;
                    uint set = leaf_byte(lo, hi, g);
                    [[unroll]] for (uint b = 0u; b < 8u; ++b) {
                        differ |= (x >> (4u * b)) & (set >> b) & 1u;
                    }
                }
                one_material = differ == 0u;
                words = 2u + (uint(bitCount(lo)) + uint(bitCount(hi)) + 7u) / 8u;
            }
            if ((lo | hi) == 0u) {
                decided = true;
            } else if ((lo & hi) == 0xFFFFFFFFu && one_material) {
                result = EDIT_FULL | first;
                decided = true;
            }
        } else {
            [[unroll]] for (uint k = 0u; k < 4u; ++k) {
                uvec2 pair = input_pair(i * 4u + k);
                c[2u * k] = pair.x;
                c[2u * k + 1u] = pair.y;
            }
            [[unroll]] for (uint o = 0u; o < 8u; ++o) {
                uint v = c[o];
                if ((v & EDIT_TAG_MASK) == EDIT_TEMP) {
                    uint j = v & EDIT_INDEX_MASK;
                    v = below_result(j);
                    if ((v & EDIT_TAG_MASK) == EDIT_PENDING && below_level != 0ul) {
                        uint r = v;
                        v = below_resolve(below_handles, below_slots, j, r);
                        missing += v == r ? 1u : 0u;
                    }
                }
                c[o] = v;
            }
            bool same = !edit_is_ptr(c[0]);
            [[unroll]] for (uint o = 1u; o < 8u; ++o) same = same && c[o] == c[0];
            if (same) {
                result = c[0];
                decided = true;
            } else {
                // Header: child mask, and the full children's bits (their word is the material).
                [[unroll]] for (uint o = 0u; o < 8u; ++o) {
                    lo |= c[o] != EDIT_EMPTY ? 1u << o : 0u;
                    lo |= edit_is_full(c[o]) ? 1u << (8u + o) : 0u;
                }
                words = 1u + uint(bitCount(lo & 0xFFu));
            }
        }
        if (!decided) {
            uint s = words - 2u;
            uint index = atomicAdd(counters.w[s], 1u);
            Words items = Words(tables.a[EDIT_LEVEL_ITEMS + s]);
            uint at = index * words;
            items.w[at] = lo;
            if (leaves) {
                items.w[at + 1u] = hi;
                if (materials) {
                    // The set voxels' materials in rank order, 8 nibbles a word: each group of 8
                    // voxels adds its nibbles to a 64-bit queue, which gives out a word when full.
                    uint64_t queue = 0ul;
                    uint queued = 0u;
                    uint next = at + 2u;
                    [[unroll]] for (uint g = 0u; g < 8u; ++g) {
                        uint set = leaf_byte(lo, hi, g);
                        uint packed = 0u;
                        uint n = 0u;
                        [[unroll]] for (uint b = 0u; b < 8u; ++b) {
                            bool on = ((set >> b) & 1u) != 0u;
                            packed |= on ? ((mats[g] >> (4u * b)) & 15u) << (4u * n) : 0u;
                            n += on ? 1u : 0u;
                        }
                        queue |= uint64_t(packed) << (4u * queued);
                        queued += n;
                        if (queued >= 8u) {
                            items.w[next] = uint(queue);
                            next += 1u;
                            queue >>= 32u;
                            queued -= 8u;
                        }
                    }
                    if (queued != 0u) {
                        items.w[next] = uint(queue);
                    }
                }
            } else {
                uint next = at + 1u;
                [[unroll]] for (uint o = 0u; o < 8u; ++o) {
                    if (c[o] != EDIT_EMPTY) {
                        items.w[next] = edit_is_full(c[o]) ? c[o] & 15u : c[o];
                        next += 1u;
                    }
                }
            }
            slots.w[i] = index;
            result = EDIT_PENDING | s;
        }
        uint at = (push.flags & EDIT_FLAG_RESULT_INDEX) != 0u ? Words(push.dst2).w[i] : i;
        results.w[at] = result;
        i += stride;
        if (i >= push.count) break;
    }
    if (missing != 0u) {
        // Children left pending (a pool ran out): counted once per invocation.
        atomicAdd(Words(below_tables.a[EDIT_LEVEL_MISSING]).w[0], missing);
    }
}
