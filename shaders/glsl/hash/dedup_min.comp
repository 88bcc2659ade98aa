#version 460
// Duplicate-detection table, pass 2 of 3 (see dedup_common.glsl): one team per input finds
// the first entry with its key along its bucket's chain (the table no longer changes, so all
// inputs with equal keys find the same entry), records it in canon[i] and folds its value into
// the entry's minimum (stored inverted: atomicMax on a zeroed word).
#include "hash/dedup_common.glsl"

void representative(uint i) {
    Words keys = Words(push.keys);
    uint slab_index = hash_key(keys, i) % push.buckets;
    for (uint links = 0u;; ++links) {
        Words slab = slab_at(slab_index);
        uint s = find_key(slab, keys, i, false);
        if (s != SLOTS) {
            if (team_leader()) {
                Words(push.canon).w[i] = slab_index * SLOTS + s;
                atomicMax(slab.w[VALUES_OFFSET + s], ~Words(push.values).w[i]);
            }
            return;
        }
        slab_index = slab.w[NEXT_OFFSET];
        bool broken = slab_index != NO_SLAB && chain_broken(links, slab_index);
        if (slab_index == NO_SLAB || broken) {
            // Unreachable after a successful pass 1: every key has an entry. Flag it, never guess.
            if (team_leader()) {
                atomicOr(Words(push.counters).w[COUNTER_OVERFLOW],
                         broken ? OVERFLOW_BROKEN_CHAIN : OVERFLOW_NO_ENTRY);
                Words(push.canon).w[i] = ~0u;
            }
            return;
        }
    }
}

void main() {
    for (uint i = team_index(); i < push.count; i += team_count()) {
        representative(i);
    }
}
