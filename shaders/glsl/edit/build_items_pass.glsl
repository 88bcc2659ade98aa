// build_items' body (edit/build_items.comp; also run for the small top levels of an edit by
// edit/merge_small_levels.comp). The includer includes edit/common.glsl first and defines the
// reads of the level's inputs: input_word(i), input_pair(k), below_result(j) and
// below_resolve(level, slots, j, r) (see edit/build_items.comp).

// Builds the items of nodes start, start + stride, ... of the level (`push`).
void edit_build_items_pass(uint start, uint stride) {
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
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = start;
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
                // The set voxels whose material differs from voxel 0's: a nibble-wise compare,
                // each voxel's bit of the mask moved to bit 0 of its nibble.
                uint differ = 0u;
                [[unroll]] for (uint g = 0u; g < 8u; ++g) {
                    uint x = mats[g] ^ (first * 0x11111111u);
                    x = (x | (x >> 1u)) & 0x55555555u;
                    x = (x | (x >> 2u)) & 0x11111111u;
                    differ |= x & leaf_byte_nibbles(leaf_byte(lo, hi, g));
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
