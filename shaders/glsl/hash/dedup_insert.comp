#version 460
// Duplicate-detection table, pass 1 of 3 (see dedup_common.glsl): one team per input.
// Slab table (subgroup teams): the cheap duplicate check scans the bucket's first slab for a
// ready slot with an equal key; when there is none the key is inserted into the first empty slot
// of the bucket's chain (claim the tag, write the key, publish the tag). Keys whose duplicate
// sits in an overflow slab, or is being written at the same time, are inserted again: pass 2
// makes all copies agree.
// Probe table (single lanes): the key is inserted at the first empty slot of its probe sequence
// unless a ready copy comes first; its hash is kept in canon[i] for pass 2.
#include "hash/dedup_common.glsl"

// Claims an empty slot of `slab` for the team: SLOTS when the slab is full.
uint claim_slot(Words slab) {
    if (TEAM == 1u) {
        for (uint s = 0; s < SLOTS; ++s) {
            if (slab.w[s] == TAG_EMPTY
                && atomicCompSwap(slab.w[s], TAG_EMPTY, TAG_WRITING) == TAG_EMPTY) {
                return s;
            }
        }
        return SLOTS;
    }
    for (uint chunk = 0; chunk < SLOTS; chunk += gl_SubgroupSize) {
        uint s = chunk + gl_SubgroupInvocationID;
        uvec4 empty = subgroupBallot(s < SLOTS && slab.w[min(s, SLOTS - 1)] == TAG_EMPTY);
        while (subgroupBallotBitCount(empty) != 0) {
            uint candidate = chunk + subgroupBallotFindLSB(empty);
            uint old = 0;
            if (subgroupElect()) {
                old = atomicCompSwap(slab.w[candidate], TAG_EMPTY, TAG_WRITING);
            }
            if (subgroupBroadcastFirst(old) == TAG_EMPTY) {
                return candidate;
            }
            // Taken meanwhile: forget that slot, try the chunk's next empty one.
            uint bit = candidate - chunk;
            empty[bit / 32] &= ~(1u << (bit % 32));
        }
    }
    return SLOTS;
}

// The next slab of `slab_index`'s chain, linking a pool slab at the end of the chain; NO_SLAB when
// the pool is exhausted. `spare` is a pool slab taken earlier but not linked (another subgroup
// linked its own first), kept for the next time.
uint next_slab(Words slab, inout uint spare) {
    uint next = 0;
    if (team_leader()) {
        next = atomicAdd(slab.w[NEXT_OFFSET], 0);
        if (next == NO_SLAB) {
            if (spare == NO_SLAB) {
                uint taken = atomicAdd(Words(push.counters).w[COUNTER_POOL_USED], 1);
                if (taken < push.pool_slabs) {
                    spare = push.buckets + taken;
                } else {
                    // The host grows the pool and runs the batch again.
                    atomicOr(Words(push.counters).w[COUNTER_OVERFLOW], OVERFLOW_POOL);
                }
            }
            if (spare != NO_SLAB) {
                uint linked = atomicCompSwap(slab.w[NEXT_OFFSET], NO_SLAB, spare);
                if (linked == NO_SLAB) {
                    next = spare;
                    spare = NO_SLAB;
                } else {
                    next = linked;
                }
            }
        }
    }
    spare = team_from_leader(spare);
    return team_from_leader(next);
}

void insert(uint i) {
    Words keys = Words(push.keys);
    uint slab_index = hash_key(keys, i) % push.buckets;
    Words slab = slab_at(slab_index);
    if (find_key(slab, keys, i, true) != SLOTS) {
        return;
    }
    uint spare = NO_SLAB;
    for (uint links = 0u;; ++links) {
        uint s = claim_slot(slab);
        if (s != SLOTS) {
            // One lane writes the key and publishes it: no ordering between lanes needed (and
            // subgroupBarrier() acts on the whole workgroup on lavapipe).
            bool leader = team_leader();
            if (leader) {
                for (uint j = 0; j < KEY_WORDS; ++j) {
                    slab.w[KEYS_OFFSET + s * KEY_WORDS + j] = keys.w[i * KEY_WORDS + j];
                }
            }
            if (TEAM > 1u) {
                memoryBarrierBuffer(); // by the whole subgroup: no barrier in divergent code
            }
            // (A single lane publishes with the atomic exchange alone: see find_key.)
            if (leader) {
                atomicExchange(slab.w[s], TAG_READY);
                atomicAdd(Words(push.counters).w[COUNTER_ENTRIES], 1);
            }
            return;
        }
        slab_index = next_slab(slab, spare);
        if (slab_index == NO_SLAB) {
            return;
        }
        if (chain_broken(links, slab_index)) {
            if (team_leader()) {
                atomicOr(Words(push.counters).w[COUNTER_OVERFLOW], OVERFLOW_BROKEN_CHAIN);
            }
            return;
        }
        slab = slab_at(slab_index);
    }
}

void probe_insert(uint i) {
    Words keys = Words(push.keys);
    Words table = Words(push.table);
    uint h = hash_key(keys, i);
    Words(push.canon).w[i] = h;
    uint ready = probe_ready_tag(h);
    uint slot = h & (push.buckets - 1u);
    uint probes = 0u;
    while (probes < push.buckets) {
        uint tag;
        slot = probe_skip(push.table, push.buckets, slot, ready, probes, tag);
        if (tag == TAG_EMPTY) {
            if (atomicCompSwap(table.w[slot], TAG_EMPTY, TAG_WRITING) == TAG_EMPTY) {
                for (uint j = 0; j < KEY_WORDS; ++j) {
                    table.w[probe_key_word(slot, j)] = keys.w[i * KEY_WORDS + j];
                }
                // Publishes the key (an atomic: lavapipe orders the stores before it, see
                // find_key).
                atomicExchange(table.w[slot], ready);
                atomicAdd(Words(push.counters).w[COUNTER_ENTRIES], 1);
                return;
            }
            // Taken meanwhile: look at the same slot again.
            continue;
        }
        // A ready tag equal to ours (the walk stops on nothing else before the bound): re-read
        // atomically before trusting the key words, as find_key does.
        if (tag == ready && atomicOr(table.w[slot], 0u) == ready
            && probe_key_equals(table, slot, keys, i)) {
            return;
        }
        slot = (slot + 1u) & (push.buckets - 1u);
        probes += 1u;
    }
    // Never with at least twice as many slots as inputs: flagged, never a wrong answer.
    atomicOr(Words(push.counters).w[COUNTER_OVERFLOW], OVERFLOW_BROKEN_CHAIN);
}

void main() {
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = team_index();
    if (i < push.count) for (;;) {
        if (TEAM == 1u) {
            probe_insert(i);
        } else {
            insert(i);
        }
        i += team_count();
        if (i >= push.count) break;
    }
}
