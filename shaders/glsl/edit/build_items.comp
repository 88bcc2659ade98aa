#version 460
// Bottom-up, one invocation per temporary node or leaf of a level: its canonical form
// (engine/edit/item.rs). Nodes whose children are all one empty or full value become EDIT_EMPTY / EDIT_FULL | m in the results; the
// others append their item to the buffer of its size and leave EDIT_PENDING | size index.
//   src      temporary nodes (8 child values) or leaves (2 mask words, + 8 material words
//            with materials (edit_materials()): nibble v = material of voxel v)
//   src2     the level below's results (EDIT_TEMP | i children read entry i; pending ones
//            are resolved here when the address buffer names the level below's, as in
//            resolve.comp, whose pass the recorded merge leaves out)
//   dst      results (one per node; at result_index[i] with EDIT_FLAG_RESULT_INDEX)
//   dst2     result_index (u32 per node)
//   tables   the level's buffer addresses (EDIT_LEVEL_* in edit/common.glsl)
//   counters 9 per-size item counts
#include "edit/common.glsl"
layout(local_size_x = 64) in;

void main() {
    Words input_words = Words(push.src);
    Words below = Words(push.src2);
    Words results = Words(push.dst);
    Addresses tables = Addresses(push.tables);
    Words counters = Words(push.counters);
    bool leaves = (push.flags & EDIT_FLAG_LEAVES) != 0u;
    bool materials = edit_materials();
    uint stride = gl_NumWorkGroups.x * 64u;
    for (uint i = gl_GlobalInvocationID.x; i < push.count; i += stride) {
        uint item[10];
        uint words = 0u;
        uint result = EDIT_EMPTY;
        bool decided = false;
        if (leaves) {
            uint rec = materials ? 10u : 2u;
            uint lo = input_words.w[i * rec];
            uint hi = input_words.w[i * rec + 1u];
            uint first = materials ? input_words.w[i * rec + 2u] & 15u : 0u;
            bool one_material = true;
            item[0] = lo;
            item[1] = hi;
            words = 2u;
            if (materials) {
                for (uint k = 2u; k < 10u; ++k) item[k] = 0u;
                uint rank = 0u;
                for (uint v = 0u; v < 64u; ++v) {
                    bool set = ((v < 32u ? lo >> v : hi >> (v - 32u)) & 1u) != 0u;
                    if (!set) continue;
                    uint m = input_words.w[i * rec + 2u + v / 8u] >> (4u * (v % 8u)) & 15u;
                    one_material = one_material && m == first;
                    item[2u + rank / 8u] |= m << (4u * (rank % 8u));
                    rank++;
                }
                words = 2u + (rank + 7u) / 8u;
            }
            if ((lo | hi) == 0u) {
                decided = true;
            } else if ((lo & hi) == 0xFFFFFFFFu && one_material) {
                result = EDIT_FULL | first;
                decided = true;
            }
        } else {
            uint c[8];
            uint64_t below_level = tables.a[EDIT_LEVEL_BELOW];
            for (uint o = 0u; o < 8u; ++o) {
                uint v = input_words.w[i * 8u + o];
                if ((v & EDIT_TAG_MASK) == EDIT_TEMP) {
                    uint j = v & EDIT_INDEX_MASK;
                    v = below.w[j];
                    if ((v & EDIT_TAG_MASK) == EDIT_PENDING && below_level != 0ul) {
                        v = edit_resolve(Addresses(below_level), j, v);
                    }
                }
                c[o] = v;
            }
            bool same = !edit_is_ptr(c[0]);
            for (uint o = 1u; o < 8u; ++o) same = same && c[o] == c[0];
            if (same) {
                result = c[0];
                decided = true;
            } else {
                uint header = 0u;
                words = 1u;
                for (uint o = 0u; o < 8u; ++o) {
                    if (c[o] == EDIT_EMPTY) continue;
                    header |= 1u << o;
                    if (edit_is_full(c[o])) {
                        header |= 1u << (8u + o);
                        item[words++] = c[o] & 15u;
                    } else {
                        item[words++] = c[o];
                    }
                }
                item[0] = header;
            }
        }
        if (!decided) {
            uint s = words - 2u;
            uint index = atomicAdd(counters.w[s], 1u);
            Words items = Words(tables.a[EDIT_LEVEL_ITEMS + s]);
            for (uint k = 0u; k < words; ++k) items.w[index * words + k] = item[k];
            Words(tables.a[EDIT_LEVEL_SLOTS]).w[i] = index;
            result = EDIT_PENDING | s;
        }
        uint at = (push.flags & EDIT_FLAG_RESULT_INDEX) != 0u ? Words(push.dst2).w[i] : i;
        results.w[at] = result;
    }
}
