#version 460
// Garbage collection, sweep: one subgroup per bucket walks its chain. In every slab it clears the
// occupied slots whose active bit is not set (all their words zero again, plus the layout's
// marker: Atomic64's prefix is part of the words, Ticket Board / Acceleration Hash clear the
// occupancy bit and the secondary hash), then either resets the active word for the next cycle
// or, when no item is left and the slab is not the bucket's first, unlinks it, zeroes it and
// returns it to the allocator (a free slab is all zeros). Nothing else runs meanwhile, and a
// chain belongs to one subgroup, so only the allocator bitmasks and counters need atomics.
#include "hash/gc_common.glsl"

bool slot_occupied(HashWords slab, uint slot) {
    if (VARIANT == HASH_ATOMIC64) {
        uint first = slab.w[hash_item_word(slot, 0u)];
        return ITEM_WORDS == 1u ? first != 0u : (first | slab.w[hash_item_word(slot, 1u)]) != 0u;
    }
    return ((slab.w[HASH_SLAB_OCCUPANCY] >> slot) & 1u) != 0u;
}

void sweep_bucket(uint bucket) {
    HashWords heads = HashWords(push.heads);
    uint slab_words = hash_slab_words();
    uint link = heads.w[bucket];
    uint prev = HASH_NO_SLAB; // previous slab kept in the chain (the first slab is always kept)
    uint freed_items = 0u;
    uint freed_slabs = 0u;
    // Read before this walk frees anything: the chain has at most that many slabs.
    uint max_links = subgroupBroadcastFirst(hash_allocated_slabs(push.status, false));
    for (uint links = 0u; link != 0u; ++links) {
        if (links == max_links || hash_link_outside(link, push.blocks)) {
            if (subgroupElect()) hash_report_broken_chain(push.status);
            break;
        }
        uint slab_index = link - 1u;
        HashWords slab = HashWords(hash_slab_address(push.super_blocks, slab_index));
        uint marked = slab.w[HASH_SLAB_ACTIVE];
        uint next = slab.w[HASH_SLAB_NEXT];
        uint occupied = 0u;
        for (uint chunk = 0u; chunk < HASH_SLAB_SLOTS; chunk += gl_SubgroupSize) {
            uint slot = chunk + gl_SubgroupInvocationID;
            bool occ = slot < HASH_SLAB_SLOTS && slot_occupied(slab, slot);
            occupied |= subgroupOr(occ ? 1u << slot : 0u);
        }
        uint garbage = occupied & ~marked;
        uint kept = occupied & marked;
        freed_items += bitCount(garbage);
        // Clear the garbage slots' words, each lane its own slots.
        for (uint chunk = 0u; chunk < HASH_SLAB_SLOTS; chunk += gl_SubgroupSize) {
            uint slot = chunk + gl_SubgroupInvocationID;
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
            for (uint w = gl_SubgroupInvocationID; w < HASH_SLAB_SLOTS / 4u; w += gl_SubgroupSize) {
                uint keep_bytes = 0u;
                for (uint b = 0u; b < 4u; ++b) {
                    keep_bytes |= ((kept >> (4u * w + b)) & 1u) != 0u ? 0xFFu << (8u * b) : 0u;
                }
                slab.w[hash_hashes_offset() + w] &= keep_bytes;
            }
        }
        if (kept == 0u && prev != HASH_NO_SLAB) {
            // Wholly empty and not the first slab: unlink, zero, free.
            for (uint w = gl_SubgroupInvocationID; w < slab_words; w += gl_SubgroupSize) {
                slab.w[w] = 0u;
            }
            if (subgroupElect()) {
                // No barrier between unlink and free: nothing allocates during the sweep (and on
                // lavapipe a memoryBarrierBuffer() in divergent code loses lanes).
                HashWords(hash_slab_address(push.super_blocks, prev)).w[HASH_SLAB_NEXT] = next;
                hash_free_slab(push.super_blocks, push.status, slab_index);
            }
            freed_slabs += 1u;
        } else {
            if (subgroupElect()) {
                if (VARIANT != HASH_ATOMIC64) {
                    slab.w[HASH_SLAB_OCCUPANCY] = kept;
                }
                slab.w[HASH_SLAB_ACTIVE] = 0u;
            }
            prev = slab_index;
        }
        link = next;
    }
    if (subgroupElect()) {
        if (freed_items != 0u) atomicAdd(HashWords(push.items).w[GC_FREED_ITEMS], freed_items);
        if (freed_slabs != 0u) atomicAdd(HashWords(push.items).w[GC_FREED_SLABS], freed_slabs);
    }
}

void main() {
    for (uint bucket = gl_WorkGroupID.x; bucket < push.buckets; bucket += gl_NumWorkGroups.x) {
        sweep_bucket(bucket);
    }
}
