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

const uint CLAIM_EMPTY = 0u;
const uint CLAIM_WRITING = 1u;

// The ready tag of an item with hash `h` (never CLAIM_EMPTY or CLAIM_WRITING).
uint claim_ready_tag(uint h) {
    return h | 2u;
}

// Word of the claim table holding word `w` of the item copied into `slot`.
uint claim_item_word(uint slot, uint w) {
    return 2u * push.claim_slots + slot * ITEM_WORDS + w;
}

// Whether `slot` holds `item` (the caller checked the tag).
bool claim_slot_equals(HashWords table, uint slot, uint item[HASH_MAX_ITEM_WORDS]) {
    for (uint w = 0u; w < ITEM_WORDS; ++w) {
        if (table.w[claim_item_word(slot, w)] != item[w]) return false;
    }
    return true;
}

// From `slot` on, the first slot whose tag is empty or `ready` (the slots between hold other
// items or copies being written); `probes` counts the slots passed and stops the walk at the
// table's size. A loop of one load per slot: the costly steps stay out of its body.
uint claim_skip(HashWords table, uint slot, uint ready, inout uint probes, out uint tag) {
    uint mask = push.claim_slots - 1u;
    tag = table.w[slot];
    while (tag != CLAIM_EMPTY && tag != ready && probes < push.claim_slots) {
        slot = (slot + 1u) & mask;
        probes += 1u;
        tag = table.w[slot];
    }
    return slot;
}

// Search-and-claim pass: makes sure the table holds a copy of item `i` (hash `h`), writing one
// at the first empty slot of its probe sequence unless a ready copy comes first.
void claim_copy(uint item[HASH_MAX_ITEM_WORDS], uint h, uint i) {
    HashWords table = HashWords(push.claims);
    uint ready = claim_ready_tag(h);
    uint mask = push.claim_slots - 1u;
    uint slot = h & mask;
    uint probes = 0u;
    while (probes < push.claim_slots) {
        uint tag;
        slot = claim_skip(table, slot, ready, probes, tag);
        if (tag == CLAIM_EMPTY) {
            if (atomicCompSwap(table.w[slot], CLAIM_EMPTY, CLAIM_WRITING) == CLAIM_EMPTY) {
                for (uint w = 0u; w < ITEM_WORDS; ++w) {
                    table.w[claim_item_word(slot, w)] = item[w];
                }
                table.w[push.claim_slots + slot] = i;
                // Publishes the copy (an atomic: lavapipe, the only single-lane user, orders
                // the stores before it; see dedup_common.glsl's find_key).
                atomicExchange(table.w[slot], ready);
                return;
            }
            // Taken meanwhile: look at the same slot again.
            continue;
        }
        // A ready tag equal to ours: re-read it atomically before trusting the item words.
        if (tag == ready && atomicOr(table.w[slot], 0u) == ready
            && claim_slot_equals(table, slot, item)) {
            return;
        }
        slot = (slot + 1u) & mask;
        probes += 1u;
    }
    // Never with at least twice as many slots as items: flagged, never a wrong answer.
    hash_report_broken_chain(push.status);
}

// Insert round with HASH_FLAG_CLAIMS (the table no longer changes): the owner of the first copy
// of `item` along its probe sequence, the same for all equal items; HASH_MISS (flagged) when
// there is none, which a completed search-and-claim pass rules out.
uint claim_owner(uint item[HASH_MAX_ITEM_WORDS], uint h) {
    HashWords table = HashWords(push.claims);
    uint ready = claim_ready_tag(h);
    uint mask = push.claim_slots - 1u;
    uint slot = h & mask;
    uint probes = 0u;
    while (probes < push.claim_slots) {
        uint tag;
        slot = claim_skip(table, slot, ready, probes, tag);
        if (tag == CLAIM_EMPTY) {
            break;
        }
        if (tag == ready && claim_slot_equals(table, slot, item)) {
            return table.w[push.claim_slots + slot];
        }
        slot = (slot + 1u) & mask;
        probes += 1u;
    }
    hash_report_broken_chain(push.status);
    return HASH_MISS;
}
