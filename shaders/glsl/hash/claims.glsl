// The claim table of a batch on single lanes (TEAM == 1; engine/hash/claim.rs): the batch's
// duplicate detection folded into the table passes. Open addressing with linear probing over
// push.claim_slots slots (a power of two, at least twice the items, so it never fills up):
//   tags[slots] | owners[slots] | items[slots][ITEM_WORDS]
// tag: 0 empty, 1 being written, else the item's hash with bit 1 set (ready: item and owner
// published). owner: index of the batch item that wrote the copy. Only the tags are zeroed.
// Copies are never removed while a batch runs, so every item finds its first copy at or after
// its home slot before any empty slot: the search-and-claim pass writes a copy unless a ready
// one comes first (a copy being written is skipped, making a second one), and the insert round
// with HASH_FLAG_CLAIMS takes the first copy's owner as the representative of all equal items.
// Include after hash/common.glsl and hash/slab.glsl.

#include "shared/probe.glsl"

// Word of the claim table holding word `w` of the item copied into `slot`.
uint claim_item_word(uint slot, uint w) {
    return 2u * push.claim_slots + slot * ITEM_WORDS + w;
}

// Whether `slot` holds `item` (the caller checked the tag).
bool claim_slot_equals(HashWords table, uint slot, uint item[HASH_MAX_ITEM_WORDS]) {
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint w = 0u; // an item has at least one word
    for (;;) {
        if (table.w[claim_item_word(slot, w)] != hash_item_word_at(item, w)) return false;
        w += 1u;
        if (w >= ITEM_WORDS) break;
    }
    return true;
}

// The owner of the first copy of `item` (hash `h`) along its probe sequence; HASH_MISS (and
// flagged) when there is none. `claim` (search-and-claim pass, while other lanes write copies):
// where an empty slot comes before any ready copy, write a copy owned by `i` there (a copy
// being written is skipped, which may make a second one). Without `claim` (insert round: the
// table no longer changes) every item of the batch that the search missed finds its copy.
uint claim_first_copy(uint item[HASH_MAX_ITEM_WORDS], uint h, uint i, bool claim) {
    HashWords table = HashWords(push.claims);
    uint ready = probe_ready_tag(h);
    uint mask = push.claim_slots - 1u;
    uint slot = h & mask;
    uint probes = 0u;
    while (probes < push.claim_slots) {
        uint tag;
        slot = probe_skip(push.claims, push.claim_slots, slot, ready, probes, tag);
        if (tag == PROBE_EMPTY) {
            if (!claim) {
                break;
            }
            if (atomicCompSwap(table.w[slot], PROBE_EMPTY, PROBE_WRITING) == PROBE_EMPTY) {
                uint w = 0u; // the exit test at the end, as in claim_slot_equals
                for (;;) {
                    table.w[claim_item_word(slot, w)] = hash_item_word_at(item, w);
                    w += 1u;
                    if (w >= ITEM_WORDS) break;
                }
                table.w[push.claim_slots + slot] = i;
                // Publishes the copy (an atomic: lavapipe, the only single-lane user, orders
                // the stores before it; see dedup_common.glsl's find_key).
                atomicExchange(table.w[slot], ready);
                return i;
            }
            // Taken meanwhile: look at the same slot again.
            continue;
        }
        // A ready tag equal to ours; while copies are being written, re-read it atomically
        // before trusting the item words.
        if (tag == ready && (!claim || atomicOr(table.w[slot], 0u) == ready)
            && claim_slot_equals(table, slot, item)) {
            return table.w[push.claim_slots + slot];
        }
        slot = (slot + 1u) & mask;
        probes += 1u;
    }
    // Never with at least twice as many slots as items, nor for an item whose copy the
    // search-and-claim pass made: flagged, never a wrong answer.
    hash_report_broken_chain(push.status);
    return HASH_MISS;
}
