// Cooperative slab scans shared by the search and insert passes: one item per team (the whole
// subgroup, or a single lane when TEAM == 1), the 32 slots of a slab looked at in chunks of
// TEAM lanes (lane l takes slot chunk + l). Include after hash/common.glsl (which brings the
// team_* helpers of shared/team.glsl).

// Whether the pass runs with the subgroup size it was specialised for (cooperative teams only).
bool team_size_ok() {
    return TEAM == 1u || gl_SubgroupSize == SUBGROUP_SIZE;
}

// Loads an item (every lane the same words): ITEM_WORDS loads, each word put in place by
// selects; the words past the item are zero.
void hash_load_item(uint64_t items, uint i, out uint item[HASH_MAX_ITEM_WORDS]) {
    HashWords src = HashWords(items);
    [[unroll]] for (uint k = 0u; k < HASH_MAX_ITEM_WORDS; ++k) {
        item[k] = 0u;
    }
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe"): in a mixed batch
    // ITEM_WORDS is a run-time value, so the loop is not unrolled.
    uint w = 0u; // an item has at least one word
    for (;;) {
        uint x = src.w[i * ITEM_WORDS + w];
        [[unroll]] for (uint k = 0u; k < HASH_MAX_ITEM_WORDS; ++k) {
            item[k] = k == w ? x : item[k];
        }
        w += 1u;
        if (w >= ITEM_WORDS) break;
    }
}

// Whether `slot` of the slab holds exactly `item`, words from `first` on.
bool hash_slot_equals(HashWords slab, uint slot, uint item[HASH_MAX_ITEM_WORDS], uint first) {
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint w = first;
    if (w < ITEM_WORDS) for (;;) {
        if (slab.w[hash_item_word(slot, w)] != hash_item_word_at(item, w)) return false;
        w += 1u;
        if (w >= ITEM_WORDS) break;
    }
    return true;
}

// Secondary hash stored in `slot` (Acceleration Hash).
uint hash_stored_secondary(HashWords slab, uint slot) {
    if (VARIANT == HASH_ACCEL32) return slab.w[hash_hashes_offset() + slot];
    return (slab.w[hash_hashes_offset() + slot / 4u] >> (8u * (slot % 4u))) & 0xFFu;
}

// The secondary hash as stored by this variant.
uint hash_secondary_stored_form(uint h) {
    uint s = hash_secondary(h);
    return VARIANT == HASH_ACCEL8 ? s & 0xFFu : s;
}

// Slots of a slab whose 8-bit secondary hash equals `sec`: four at a time per word (bit s =
// slot s), with the exact zero-byte test of x = word ^ (sec in every byte).
uint hash_accel8_candidates(HashWords words, uint sec) {
    uint hits = 0u;
    uint pattern = sec * 0x01010101u;
    for (uint g = 0u; g < HASH_SLAB_SLOTS / 4u; ++g) {
        uint x = words.w[hash_hashes_offset() + g] ^ pattern;
        uint zero = ~(((x & 0x7F7F7F7Fu) + 0x7F7F7F7Fu) | x | 0x7F7F7F7Fu); // 0x80 per zero byte
        uint four = ((zero >> 7u) & 1u) | ((zero >> 14u) & 2u) | ((zero >> 21u) & 4u)
                  | ((zero >> 28u) & 8u);
        hits |= four << (4u * g);
    }
    return hits;
}

// One lane alone (TEAM == 1), occupancy-mask layouts: visit only occupied slots (Accel8: only
// those whose hash byte matches), comparing the secondary hash before the item.
uint hash_find_in_slab_single(HashWords words, uint slab, uint item[HASH_MAX_ITEM_WORDS],
                              uint sec) {
    uint candidates = words.w[HASH_SLAB_OCCUPANCY];
    if (VARIANT == HASH_ACCEL8) {
        candidates &= hash_accel8_candidates(words, sec);
    }
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    if (candidates != 0u) for (;;) {
        uint slot = uint(findLSB(candidates));
        candidates &= candidates - 1u;
        if ((VARIANT != HASH_ACCEL32 || words.w[hash_hashes_offset() + slot] == sec)
            && hash_slot_equals(words, slot, item, 0u)) {
            return (slab << 5u) | slot;
        }
        if (candidates == 0u) break;
    }
    return HASH_MISS;
}

// Four 64-bit prefixes of an Atomic64 slab per load (from the slab's second 64-bit word).
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer HashPrefixes4 {
    u64vec4 v[];
};

// One lane alone, Atomic64 with 64-bit prefixes: the prefixes read four at a time (a load
// through a buffer address is a loop over the SIMD lanes on lavapipe: 8 per slab instead of
// 32). Inserts claim the lowest empty slot and only GC empties one (HASH_FLAG_HOLES), so
// without holes the items are a prefix of the slab and an empty prefix ends the scan (and the
// chain: a slab gets a successor only once full).
uint hash_find_in_slab_atomic64_single(uint64_t slab_addr, uint slab,
                                       uint item[HASH_MAX_ITEM_WORDS]) {
    HashWords words = HashWords(slab_addr);
    HashPrefixes4 prefixes = HashPrefixes4(slab_addr + 8ul);
    uint64_t prefix = packUint2x32(uvec2(item[0], item[1]));
    bool holes = (push.flags & HASH_FLAG_HOLES) != 0u;
    for (uint g = 0u; g < HASH_SLAB_SLOTS / 4u; ++g) {
        u64vec4 p = prefixes.v[g];
        for (uint k = 0u; k < 4u; ++k) {
            if (p[k] == prefix && hash_slot_equals(words, 4u * g + k, item, 2u)) {
                return (slab << 5u) | (4u * g + k);
            }
        }
        if (!holes && any(equal(p, u64vec4(0ul)))) {
            break;
        }
    }
    return HASH_MISS;
}

// Handle of `item` in the slab at `slab_addr` (index `slab`), or HASH_MISS. Team-uniform.
uint hash_find_in_slab(uint64_t slab_addr, uint slab, uint item[HASH_MAX_ITEM_WORDS], uint sec) {
    HashWords words = HashWords(slab_addr);
    if (TEAM == 1u && VARIANT != HASH_ATOMIC64) {
        return hash_find_in_slab_single(words, slab, item, sec);
    }
    if (TEAM == 1u && hash_prefix64()) {
        return hash_find_in_slab_atomic64_single(slab_addr, slab, item);
    }
    uint occupancy = VARIANT == HASH_ATOMIC64 ? 0u : words.w[HASH_SLAB_OCCUPANCY];
    uint64_t prefix = hash_prefix64() ? packUint2x32(uvec2(item[0], item[1])) : 0ul;
    for (uint chunk = 0u; chunk < HASH_SLAB_SLOTS; chunk += TEAM) {
        uint slot = chunk + team_lane();
        bool match = false;
        if (slot < HASH_SLAB_SLOTS) {
            if (hash_prefix64()) {
                match = HashWords64(slab_addr).w[1u + slot] == prefix
                     && hash_slot_equals(words, slot, item, 2u);
            } else if (VARIANT == HASH_ATOMIC64) {
                match = words.w[hash_item_word(slot, 0u)] == item[0];
            } else if (((occupancy >> slot) & 1u) != 0u) {
                // Acceleration Hash: the item words are read only on a secondary-hash match.
                match = (VARIANT == HASH_TICKET_BOARD || hash_stored_secondary(words, slot) == sec)
                     && hash_slot_equals(words, slot, item, 0u);
            }
        }
        if (team_any(match)) {
            return (slab << 5u) | (chunk + team_first(match));
        }
    }
    return HASH_MISS;
}

// Handle of `item` (hash `h`) in the table, or HASH_MISS: its bucket's chain walked slab by
// slab. No insert may run meanwhile (the allocated-slab counter bounds the walk exactly).
uint hash_search_chain(uint item[HASH_MAX_ITEM_WORDS], uint h) {
    HashWords heads = HashWords(push.heads);
    uint sec = hash_secondary_stored_form(h);
    uint link = heads.w[h % push.buckets];
    uint max_links = hash_allocated_slabs(push.status, false);
    uint found = HASH_MISS;
    uint links = 0u;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    if (link != 0u) for (;;) {
        if (links == max_links || hash_link_outside(link, push.blocks)) {
            if (team_leader()) hash_report_broken_chain(push.status);
            break;
        }
        uint64_t addr = hash_slab_address(push.super_blocks, link - 1u);
        found = hash_find_in_slab(addr, link - 1u, item, sec);
        link = HashWords(addr).w[HASH_SLAB_NEXT];
        links += 1u;
        if (link == 0u || found != HASH_MISS) break;
    }
    return found;
}
