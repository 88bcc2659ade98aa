#version 460
// Garbage collection, sweep: one team (the whole subgroup, or one lane: TEAM) per bucket walks
// its chain. In every slab it clears the occupied slots whose active bit is not set (all their
// words zero again, plus the layout's marker: Atomic64's prefix is part of the words, Ticket
// Board / Acceleration Hash clear the occupancy bit and the secondary hash), then either resets the active word for the next cycle
// or, when no item is left, unlinks it (from the bucket head for the first slab), zeroes it and
// returns it to the allocator (a free slab is all zeros). Nothing else runs meanwhile, and a
// chain belongs to one team, so only the allocator bitmasks and counters need atomics.
#include "hash/gc_common.glsl"

// Bitwise or over the team.
uint team_or(uint v) {
    if (TEAM == 1u) return v;
    return subgroupOr(v);
}

// Occupied slots of a slab: the occupancy mask, or (Atomic64) the non-zero prefixes, each lane
// testing its slots of every chunk (a 2+-word prefix read as one 64-bit word).
uint occupied_slots(uint64_t slab_addr) {
    HashWords slab = HashWords(slab_addr);
    if (VARIANT != HASH_ATOMIC64) {
        return slab.w[HASH_SLAB_OCCUPANCY];
    }
    uint occupied = 0u;
    for (uint chunk = 0u; chunk < HASH_SLAB_SLOTS; chunk += TEAM) {
        uint slot = chunk + team_lane();
        bool occ = false;
        if (slot < HASH_SLAB_SLOTS) {
            occ = hash_prefix64() ? HashWords64(slab_addr).w[1u + slot] != 0ul
                                  : slab.w[hash_item_word(slot, 0u)] != 0u;
        }
        occupied |= team_or(occ ? 1u << slot : 0u);
    }
    return occupied;
}

void sweep_bucket(uint bucket) {
    HashWords heads = HashWords(push.heads);
    uint slab_words = hash_slab_words();
    uint link = heads.w[bucket];
    uint prev = HASH_NO_SLAB; // previous slab kept in the chain (none: the bucket head links)
    uint freed_items = 0u;
    uint freed_slabs = 0u;
    uint kept_items = 0u;
    // Read before this walk frees anything: the chain has at most that many slabs.
    uint max_links = team_from_leader(hash_allocated_slabs(push.status, false));
    for (uint links = 0u; link != 0u; ++links) {
        if (links == max_links || hash_link_outside(link, push.blocks)) {
            if (team_leader()) hash_report_broken_chain(push.status);
            break;
        }
        uint slab_index = link - 1u;
        uint64_t slab_addr = hash_slab_address(push.super_blocks, slab_index);
        HashWords slab = HashWords(slab_addr);
        uint marked = slab.w[HASH_SLAB_ACTIVE];
        uint next = slab.w[HASH_SLAB_NEXT];
        uint occupied = occupied_slots(slab_addr);
        uint garbage = occupied & ~marked;
        uint kept = occupied & marked;
        freed_items += bitCount(garbage);
        kept_items += bitCount(kept);
        // Clear the garbage slots' words, each lane its own slots.
        for (uint chunk = 0u; chunk < HASH_SLAB_SLOTS; chunk += TEAM) {
            uint slot = chunk + team_lane();
            if (slot < HASH_SLAB_SLOTS && ((garbage >> slot) & 1u) != 0u) {
                for (uint w = 0u; w < ITEM_WORDS; ++w) {
                    slab.w[hash_item_word(slot, w)] = 0u;
                }
                if (VARIANT == HASH_ACCEL32) {
                    slab.w[hash_hashes_offset() + slot] = 0u;
                }
            }
        }
        // Accel8 packs four slots' hash bytes per word: one lane per word.
        if (VARIANT == HASH_ACCEL8) {
            for (uint w = team_lane(); w < HASH_SLAB_SLOTS / 4u; w += TEAM) {
                uint keep_bytes = 0u;
                for (uint b = 0u; b < 4u; ++b) {
                    keep_bytes |= ((kept >> (4u * w + b)) & 1u) != 0u ? 0xFFu << (8u * b) : 0u;
                }
                slab.w[hash_hashes_offset() + w] &= keep_bytes;
            }
        }
        if (kept == 0u) {
            // Wholly empty: unlink (a bucket's first slab too, so GC gives back the slabs of
            // buckets left empty; inserts start an empty bucket's chain again), zero, free.
            for (uint w = team_lane(); w < slab_words; w += TEAM) {
                slab.w[w] = 0u;
            }
            if (team_leader()) {
                // No barrier between unlink and free: nothing allocates during the sweep (and on
                // lavapipe a memoryBarrierBuffer() in divergent code loses lanes).
                if (prev == HASH_NO_SLAB) {
                    heads.w[bucket] = next;
                } else {
                    HashWords(hash_slab_address(push.super_blocks, prev)).w[HASH_SLAB_NEXT] = next;
                }
                hash_free_slab(push.super_blocks, push.status, slab_index);
            }
            freed_slabs += 1u;
        } else {
            if (team_leader()) {
                if (VARIANT != HASH_ATOMIC64) {
                    slab.w[HASH_SLAB_OCCUPANCY] = kept;
                }
                slab.w[HASH_SLAB_ACTIVE] = 0u;
            }
            prev = slab_index;
        }
        link = next;
    }
    if (team_leader()) {
        if (freed_items != 0u) atomicAdd(GcCountersRef(push.items).freed_items, freed_items);
        if (freed_slabs != 0u) atomicAdd(GcCountersRef(push.items).freed_slabs, freed_slabs);
        if (kept_items != 0u) atomicAdd(GcCountersRef(push.items).kept_items, kept_items);
    }
}

void main() {
    if (!team_size_ok()) {
        HashStatus(push.status).subgroup_mismatch = gl_SubgroupSize;
        return;
    }
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint bucket = team_index();
    if (bucket < push.buckets) for (;;) {
        sweep_bucket(bucket);
        bucket += team_count();
        if (bucket >= push.buckets) break;
    }
}
