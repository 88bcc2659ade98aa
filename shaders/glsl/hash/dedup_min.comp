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

void probe_representative(uint i) {
    Words keys = Words(push.keys);
    Words table = Words(push.table);
    uint h = Words(push.canon).w[i];
    uint ready = probe_ready_tag(h);
    uint slot = h & (push.buckets - 1u);
    uint probes = 0u;
    while (probes < push.buckets) {
        uint tag;
        slot = probe_skip(push.table, push.buckets, slot, ready, probes, tag);
        if (tag == TAG_EMPTY) {
            break;
        }
        if (tag == ready && probe_key_equals(table, slot, keys, i)) {
            Words(push.canon).w[i] = slot;
            atomicMax(table.w[push.buckets + slot], ~Words(push.values).w[i]);
            return;
        }
        slot = (slot + 1u) & (push.buckets - 1u);
        probes += 1u;
    }
    // Unreachable after pass 1 (every key has a copy before the first empty slot): flagged.
    atomicOr(Words(push.counters).w[COUNTER_OVERFLOW],
             probes < push.buckets ? OVERFLOW_NO_ENTRY : OVERFLOW_BROKEN_CHAIN);
    Words(push.canon).w[i] = ~0u;
}

void main() {
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = team_index();
    if (i < push.count) for (;;) {
        if (TEAM == 1u) {
            probe_representative(i);
        } else {
            representative(i);
        }
        i += team_count();
        if (i >= push.count) break;
    }
}
