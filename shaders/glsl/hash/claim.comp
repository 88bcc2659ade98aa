#version 460
// Search-and-claim pass (single lanes; engine/hash/claim.rs): handles[i] = handle of items[i]
// in the table, or HASH_MISS; every missing item also gets a copy in the claim table
// (hash/claims.glsl), so that the insert round that follows (HASH_FLAG_CLAIMS) inserts one
// representative per distinct item. reps[i] = i (the insert round overwrites the missing
// items' entries with their representative). The batch's duplicate detection thus costs no
// pass of its own. A mixed batch (engine/hash/mixed.rs) runs this for items of every size.
// Driven by engine/hash/table.rs and engine/hash/mixed.rs.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require

#include "shared/hash_layout.h"
#include "hash/common.glsl"
#include "hash/slab.glsl"
#include "hash/claims.glsl"

void main() {
    // Single lanes only (TEAM == 1): the host makes this pipeline for no other team size.
    uint batch_count = hash_count();
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint k = team_index();
    if (k < batch_count) for (;;) {
        uint i = hash_select(k);
        HashWords handles = HashWords(push.handles);
        HashWords reps = HashWords(push.reps);
        uint item[HASH_MAX_ITEM_WORDS];
        hash_load_item(push.items, i, item);
        uint found = HASH_MISS;
        // Invalid items are left to the insert round, which rejects and counts them.
        if (hash_item_valid(item)) {
            uint h = hash_item(item);
            found = hash_search_chain(item, h);
            if (found == HASH_MISS) {
                claim_first_copy(item, h, i, true);
            }
        }
        handles.w[i] = found;
        reps.w[i] = i;
        k += team_count();
        if (k >= batch_count) break;
    }
}
