// The search-and-claim pass's body (hash/claim.comp; also run before the insert round by
// hash/claim_insert.comp). The includer includes shared/hash_layout.h, hash/common.glsl,
// hash/slab.glsl and hash/claims.glsl first.

// The pass: every item of the batch (grid stride), single lanes; `batch_count` from hash_count.
void hash_claim_pass(uint batch_count) {
    // Single lanes only (TEAM == 1): the host makes this pipeline for no other team size.
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
