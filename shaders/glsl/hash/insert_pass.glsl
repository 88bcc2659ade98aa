// The slab hash insert pass's body (hash/insert.comp; also run after the search and claim by
// hash/claim_insert.comp). The includer includes shared/hash_layout.h, hash/common.glsl,
// hash/alloc.glsl, hash/slab.glsl and hash/claims.glsl first.

// Writes the item words the claim did not write, lanes in parallel.
void write_item(HashWords slab, uint slot, uint item[HASH_MAX_ITEM_WORDS], uint first) {
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint w = first + team_lane();
    if (w < ITEM_WORDS) for (;;) {
        slab.w[hash_item_word(slot, w)] = hash_item_word_at(item, w);
        w += TEAM;
        if (w >= ITEM_WORDS) break;
    }
}

// Atomic64: whether `slot` holds no item (its prefix, or its only word, is zero).
bool slot_empty_atomic64(uint64_t slab_addr, uint slot) {
    return hash_prefix64() ? HashWords64(slab_addr).w[1u + slot] == 0ul
                           : HashWords(slab_addr).w[hash_item_word(slot, 0u)] == 0u;
}

// Atomic64: CAS the item's prefix (its only word) into `slot`; whether it was still empty.
bool cas_atomic64(uint64_t slab_addr, uint slot, uint item[HASH_MAX_ITEM_WORDS]) {
    if (hash_prefix64()) {
        uint64_t prefix = packUint2x32(uvec2(item[0], item[1]));
        return atomicCompSwap(HashWords64(slab_addr).w[1u + slot], 0ul, prefix) == 0ul;
    }
    return atomicCompSwap(HashWords(slab_addr).w[hash_item_word(slot, 0u)], 0u, item[0]) == 0u;
}

// Atomic64, one lane alone: claim an empty slot from `first` on; HASH_MISS when none is left.
uint claim_atomic64_single(uint64_t slab_addr, uint first, uint item[HASH_MAX_ITEM_WORDS]) {
    for (uint slot = first; slot < HASH_SLAB_SLOTS; ++slot) {
        if (slot_empty_atomic64(slab_addr, slot) && cas_atomic64(slab_addr, slot, item)) {
            return slot;
        }
    }
    return HASH_MISS;
}

// Atomic64, one lane alone: the first empty slot of a slab whose items form a prefix (inserts
// claim the lowest empty slot; only GC punches holes): a binary search of 5 loads instead of a
// scan of up to 32. Only without holes (HASH_FLAG_HOLES clear).
uint first_empty_atomic64(uint64_t slab_addr) {
    uint lo = 0u;
    uint hi = HASH_SLAB_SLOTS;
    for (;;) {
        uint mid = (lo + hi) / 2u;
        if (slot_empty_atomic64(slab_addr, mid)) {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
        if (lo >= hi) break;
    }
    return lo;
}

// Atomic64, the whole team: claim an empty prefix with a CAS, slots scanned in chunks of TEAM;
// returns the slot or HASH_MISS when the slab is full.
uint claim_atomic64_team(uint64_t slab_addr, uint item[HASH_MAX_ITEM_WORDS]) {
    for (uint chunk = 0u; chunk < HASH_SLAB_SLOTS; chunk += TEAM) {
        uint slot = chunk + team_lane();
        bool empty = slot < HASH_SLAB_SLOTS && slot_empty_atomic64(slab_addr, slot);
        while (team_any(empty)) {
            uint winner = team_first(empty);
            uint won = HASH_MISS;
            if (team_lane() == winner) {
                won = cas_atomic64(slab_addr, slot, item) ? slot : HASH_MISS;
                empty = false;
            }
            won = team_min(won);
            if (won != HASH_MISS) {
                return won;
            }
        }
    }
    return HASH_MISS;
}

// Ticket Board / Acceleration Hash: claim a clear occupancy bit; slot or HASH_MISS when full.
uint claim_ticket(HashWords words) {
    uint slot = HASH_MISS;
    if (team_leader()) {
        uint mask = words.w[HASH_SLAB_OCCUPANCY];
        while (mask != 0xFFFFFFFFu) {
            uint bit = 1u << uint(findLSB(~mask));
            uint old = atomicOr(words.w[HASH_SLAB_OCCUPANCY], bit);
            if ((old & bit) == 0u) {
                slot = uint(findLSB(bit));
                break;
            }
            mask = old | bit;
        }
    }
    return team_from_leader(slot);
}

// Atomic64 has no occupancy mask: whether a slab's last slot is empty. Slots are claimed lowest
// first and only cleared by garbage collection, so a taken last slot means a full slab unless GC
// punched holes since (HASH_FLAG_HOLES).
bool last_slot_empty(uint64_t slab_addr) {
    return slot_empty_atomic64(slab_addr, HASH_SLAB_SLOTS - 1u);
}

// Inserts one item; returns its handle, or HASH_MISS when the pool is exhausted or the chain
// loops (counted in status.exhausted / status.broken_chains). Words other teams may be writing
// (links, slots, hints) are read by the leader and broadcast, so the team never diverges.
// The walk starts at the bucket's hint (push.tails): the slab that last took an item of the
// bucket. Every slab before it was full when an insert walked past it, and only garbage
// collection (which clears the hints) empties a slot, so the walk skips nothing it could use;
// without the hint every insert walked the whole chain (3-4 slabs at load factor 96).
uint insert_item(uint item[HASH_MAX_ITEM_WORDS], uint h, uint rng) {
    uint bucket = h % push.buckets;
    HashWords tails = HashWords(push.tails);
    HashWords link_words = HashWords(push.heads);
    uint link_index = bucket;
    uint start = team_from_leader(tails.w[bucket]);
    uint link = start != 0u ? start : team_from_leader(link_words.w[link_index]);
    // Atomic64 has no occupancy mask. Without holes (no GC since the table was built) the items
    // of a slab form a prefix: a taken last slot means a full slab (one load instead of 32) and
    // a binary search finds the first empty slot. After GC (push.flags) every slot is scanned.
    bool thorough = VARIANT != HASH_ATOMIC64 || (push.flags & HASH_FLAG_HOLES) != 0u;
    // Each step of a walk follows one link or links a new slab (a lost race means the chain
    // grew): a walk of more than 2 * allocated + 2 steps goes round a loop. The bound is
    // re-read (others allocate meanwhile) before the walk is declared broken.
    uint max_links = team_from_leader(hash_allocated_slabs(push.status, false));
    for (uint step = 0u;; ++step) {
        if (step > 2u * max_links + 2u) {
            max_links = team_from_leader(team_leader() ? hash_allocated_slabs(push.status, true) : 0u);
        }
        if (step > 2u * max_links + 2u || hash_link_outside(link, push.blocks)) {
            if (team_leader()) hash_report_broken_chain(push.status);
            return HASH_MISS;
        }
        if (link == 0u) {
            // End of the chain: allocate a zeroed slab and link it with a CAS.
            uint result = 0u;
            if (team_leader()) {
                uint slab = hash_alloc_slab(push.super_blocks, push.status, push.blocks,
                                            rng + step * 0x632be5abu);
                if (slab == HASH_NO_SLAB) {
                    atomicAdd(HashStatus(push.status).exhausted, 1u);
                } else {
                    result = atomicCompSwap(link_words.w[link_index], 0u, slab + 1u);
                    if (result != 0u) {
                        hash_free_slab(push.super_blocks, push.status, slab); // lost the race
                    } else {
                        result = slab + 1u;
                    }
                }
            }
            link = team_from_leader(result);
            if (link == 0u) {
                return HASH_MISS;
            }
        }
        uint slab = link - 1u;
        uint64_t addr = hash_slab_address(push.super_blocks, slab);
        HashWords words = HashWords(addr);
        uint slot = HASH_MISS;
        if (VARIANT == HASH_ATOMIC64) {
            if (TEAM == 1u) {
                if (thorough) {
                    slot = claim_atomic64_single(addr, 0u, item);
                } else if (last_slot_empty(addr)) {
                    slot = claim_atomic64_single(addr, first_empty_atomic64(addr), item);
                }
            } else if (thorough || team_from_leader(last_slot_empty(addr) ? 1u : 0u) != 0u) {
                slot = claim_atomic64_team(addr, item);
            }
            if (slot != HASH_MISS) {
                write_item(words, slot, item, hash_prefix64() ? 2u : 1u);
            }
        } else {
            slot = claim_ticket(words);
            if (slot != HASH_MISS) {
                write_item(words, slot, item, 0u);
                uint sec = hash_secondary_stored_form(h);
                if (team_leader()) {
                    if (VARIANT == HASH_ACCEL32) {
                        words.w[hash_hashes_offset() + slot] = sec;
                    } else if (VARIANT == HASH_ACCEL8) {
                        // Four slots share a word: OR the byte in (it starts at zero).
                        atomicOr(words.w[hash_hashes_offset() + slot / 4u], sec << (8u * (slot % 4u)));
                    }
                }
            }
        }
        if (slot != HASH_MISS) {
            // A racing insert may store an earlier slab of the chain: still a valid hint.
            if (link != start && team_leader()) {
                tails.w[bucket] = link;
            }
            return (slab << 5u) | slot;
        }
        link_words = words;
        link_index = HASH_SLAB_NEXT;
        link = team_from_leader(words.w[HASH_SLAB_NEXT]);
    }
    return HASH_MISS;
}

// Inserts batch item `i` unless the search found it (a claimed batch: unless another copy
// owns it); its handle, HASH_INVALID, or HASH_MISS (exhausted) goes to handles[i].
void insert_batch_item(uint i) {
    HashWords handles = HashWords(push.handles);
    if (handles.w[i] != HASH_MISS) {
        return;
    }
    uint item[HASH_MAX_ITEM_WORDS];
    hash_load_item(push.items, i, item);
    uint handle;
    if (!hash_item_valid(item)) {
        handle = HASH_INVALID;
        if (team_leader()) {
            atomicAdd(HashStatus(push.status).invalid_items, 1u);
        }
    } else {
        uint h = hash_item(item);
        if (TEAM == 1u && (push.flags & HASH_FLAG_CLAIMS) != 0u) {
            // Only the owner of the item's first claim-table copy inserts it; the other
            // copies name it as their representative.
            uint owner = claim_first_copy(item, h, i, false);
            HashWords(push.reps).w[i] = owner;
            if (owner != i) {
                handles.w[i] = HASH_INVALID;
                return;
            }
        }
        handle = insert_item(item, h, murmur_fmix32(push.seed ^ (i * 0x9e3779b9u)));
    }
    if (team_leader()) {
        handles.w[i] = handle;
    }
}

// The pass: every item of the batch (grid stride), one per team; `batch_count` from hash_count.
void hash_insert_pass(uint batch_count) {
    if (!team_size_ok()) {
        HashStatus(push.status).subgroup_mismatch = gl_SubgroupSize;
        return;
    }
    uint stride = team_count();
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint k = team_index();
    if (k < batch_count) for (;;) {
        insert_batch_item(hash_select(k));
        k += stride;
        if (k >= batch_count) break;
    }
}
