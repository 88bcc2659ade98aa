// Slab hash tables: specialization constants, slab addressing and the item hash.
// Twin of engine/hash/layout.rs. Include after shared/hash_layout.h.
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_EXT_control_flow_attributes : require

// Specialization constants shared by every hash pass.
layout(local_size_x_id = 0) in;                     // workgroup size (a multiple of SUBGROUP_SIZE)
layout(constant_id = 1) const uint SUBGROUP_SIZE = 32;
layout(constant_id = 2) const uint VARIANT = 0;     // HASH_ATOMIC64 ...
layout(constant_id = 3) const uint SPEC_ITEM_WORDS = 1;  // 1..10; 0: a mixed batch
// Lanes that cooperate on one item: SUBGROUP_SIZE (the cooperative algorithm), or 1 (every
// lane its own item, no subgroup operations: faster on CPU implementations such as lavapipe).
layout(constant_id = 4) const uint TEAM = 32;

#define HASH_MAX_ITEM_WORDS 10
// Entries of a mixed batch (`MIXED_SIZES` in engine/hash/mixed.rs).
#define HASH_MIXED_SIZES 9u

#include "shared/murmur.glsl"
#include "shared/team.glsl"

// Parameters of every hash pass (`HashPush` in engine/hash/gpu_shared.rs).
struct HashParams { HASH_PUSH_MEMBERS };
#ifndef HASH_PARAMS_IN_MEMORY
layout(push_constant, std430) uniform Push { HashParams batch; } pc;
#endif

// The table and buffers the pass works on: the push constants, or in a mixed batch (the
// claim passes over items of every size, engine/hash/mixed.rs) the entry of the current
// item's size, which hash_select sets together with ITEM_WORDS. With HASH_PARAMS_IN_MEMORY
// (a shader that runs the passes of several batches: edit/merge_small_levels.comp) the
// includer sets it before each pass.
#ifdef HASH_PARAMS_IN_MEMORY
HashParams push;
#else
HashParams push = pc.batch;
#endif
uint ITEM_WORDS = SPEC_ITEM_WORDS;

// Whether the pipeline runs mixed batches.
bool hash_mixed() {
    return SPEC_ITEM_WORDS == 0u;
}

layout(buffer_reference, std430, buffer_reference_align = 4) coherent buffer HashWords {
    uint w[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) coherent buffer HashWords64 {
    uint64_t w[];
};

layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer HashEntries {
    HashParams entry[];
};

#ifdef HASH_PARAMS_IN_MEMORY
// The current batch's entry of item size index `s`, defined by the includer (its records).
HashParams hash_level_entry(uint s);
#endif

// A mixed batch's per-size counts and entries, read once by hash_count: a read through a
// buffer address is a loop over the SIMD lanes on lavapipe unless the address is the same
// for every lane (here: push constants and constant indices, at the top of main), and
// hash_select needs them per item.
uint g_mixed_counts[HASH_MIXED_SIZES];
HashParams g_mixed_entries[HASH_MIXED_SIZES];

// Items of the batch: push.count, or in a mixed batch the sum of its sizes' counts, which an
// earlier pass wrote at count_at. Call before hash_select, while `push` is the batch's.
uint hash_count() {
    if (!hash_mixed()) {
        return push.count;
    }
    HashWords counts = HashWords(push.count_at);
    uint total = 0u;
#ifndef HASH_PARAMS_IN_MEMORY
    HashEntries entries = HashEntries(push.mixed);
#endif
    [[unroll]] for (uint s = 0u; s < HASH_MIXED_SIZES; ++s) {
        g_mixed_counts[s] = counts.w[s];
#ifdef HASH_PARAMS_IN_MEMORY
        // With params in memory (edit/merge_small_levels.comp) this runs inside the includer's
        // loop, where the entries come from its records (texels); the `if` saves the fetches
        // of the sizes without items (hash_select never picks them). At the top of main (push
        // constants) a read through the address is one load for all lanes, but inside an `if`
        // it would go lane by lane.
        if (g_mixed_counts[s] != 0u) {
            g_mixed_entries[s] = hash_level_entry(s);
        }
#else
        g_mixed_entries[s] = entries.entry[s];
#endif
        total += g_mixed_counts[s];
    }
    return total;
}

// Item `i` of the batch: in a mixed batch, selects its size's entry (push, ITEM_WORDS) and
// returns its index among the items of that size; otherwise `i`.
uint hash_select(uint i) {
    if (!hash_mixed()) {
        return i;
    }
    // Unrolled, with constant indices: no loads, no dynamic register indexing.
    uint s = 0u;
    push = g_mixed_entries[0];
    [[unroll]] for (uint k = 0u; k + 1u < HASH_MIXED_SIZES; ++k) {
        if (s == k && i >= g_mixed_counts[k]) {
            i -= g_mixed_counts[k];
            s = k + 1u;
            push = g_mixed_entries[k + 1u];
        }
    }
    ITEM_WORDS = push.item_words;
    return i;
}

// Atomic64 with 2+ words: a 64-bit prefix per slot; 1-word Atomic64 claims 32-bit words.
bool hash_prefix64() {
    return VARIANT == HASH_ATOMIC64 && ITEM_WORDS >= 2u;
}

// First word of the per-slot secondary hashes (Acceleration Hash).
uint hash_hashes_offset() {
    return 4u;
}

// First word of the item storage.
uint hash_items_offset() {
    if (VARIANT == HASH_ATOMIC64) return 2u;
    if (VARIANT == HASH_TICKET_BOARD) return 4u;
    if (VARIANT == HASH_ACCEL32) return 4u + HASH_SLAB_SLOTS;
    return 4u + HASH_SLAB_SLOTS / 4u;
}

// Words per slab (even: 64-bit prefixes stay 8-byte aligned).
uint hash_slab_words() {
    uint end = hash_prefix64() ? 2u + 2u * HASH_SLAB_SLOTS + HASH_SLAB_SLOTS * (ITEM_WORDS - 2u)
                               : hash_items_offset() + HASH_SLAB_SLOTS * ITEM_WORDS;
    return (end + 1u) & ~1u;
}

// Word of the slab holding word w of the item in slot.
uint hash_item_word(uint slot, uint w) {
    uint items = hash_items_offset();
    if (hash_prefix64()) {
        return w < 2u ? items + 2u * slot + w
                      : items + 2u * HASH_SLAB_SLOTS + slot * (ITEM_WORDS - 2u) + (w - 2u);
    }
    return items + slot * ITEM_WORDS + w;
}

// Chain walks are bounded: no bucket chain has more slabs than status.allocated_slabs (the
// allocator counts a slab, then a fence orders that before the CAS that links it) nor links
// outside the pool. A walk past the bound is a loop in a corrupt table: it stops and counts
// itself in status.broken_chains, which the host turns into HashError::CorruptTable.
// (lavapipe also cuts any loop nest after 65535 iterations, silently: a tight bound keeps
// the flag ahead of that.)
uint hash_allocated_slabs(uint64_t status, bool fresh) {
    return fresh ? atomicAdd(HashStatus(status).allocated_slabs, 0u)
                 : HashStatus(status).allocated_slabs;
}

// Whether a link leaves the pool of `blocks` memory blocks (links are slab + 1).
bool hash_link_outside(uint link, uint blocks) {
    return link > blocks * HASH_SLABS_PER_BLOCK;
}

void hash_report_broken_chain(uint64_t status) {
    atomicAdd(HashStatus(status).broken_chains, 1u);
}

// Device address of a super block buffer.
uint64_t hash_super_block(uint64_t super_blocks, uint sb) {
    return HashWords64(super_blocks).w[sb];
}

// Device address of a slab.
uint64_t hash_slab_address(uint64_t super_blocks, uint slab) {
    uint64_t base = hash_super_block(super_blocks, slab / HASH_SLABS_PER_SUPER_BLOCK);
    uint local = slab % HASH_SLABS_PER_SUPER_BLOCK;
    return base + uint64_t(HASH_SUPER_BLOCK_BITMASK_WORDS * 4u)
         + uint64_t(local) * uint64_t(hash_slab_words() * 4u);
}

// Items live in register arrays indexed only by constants: an array indexed by a run-time
// value (ITEM_WORDS differs per item in a mixed batch) is a loop over the SIMD lanes at every
// access on lavapipe, so loops over an item's words are unrolled to HASH_MAX_ITEM_WORDS with
// a test, or read a word through `hash_item_word_at`.

// Word w of an item held in registers: one select per possible word.
uint hash_item_word_at(uint item[HASH_MAX_ITEM_WORDS], uint w) {
    uint v = 0u;
    [[unroll]] for (uint k = 0u; k < HASH_MAX_ITEM_WORDS; ++k) {
        v = k == w ? item[k] : v;
    }
    return v;
}

// Primary hash: murmur3-style mix of every word (twin of layout::hash_item).
uint hash_item(uint item[HASH_MAX_ITEM_WORDS]) {
    uint h = HASH_SEED ^ ITEM_WORDS;
    [[unroll]] for (uint i = 0u; i < HASH_MAX_ITEM_WORDS; ++i) {
        h = i < ITEM_WORDS ? murmur_mix(h, item[i]) : h;
    }
    return murmur_fmix32(h);
}

uint hash_secondary(uint h) {
    return murmur_fmix32(h ^ HASH_SECONDARY_SALT);
}

// Whether the layout can store the item (Atomic64 reserves the all-zero prefix for "empty").
bool hash_item_valid(uint item[HASH_MAX_ITEM_WORDS]) {
    if (VARIANT != HASH_ATOMIC64) return true;
    return ITEM_WORDS == 1u ? item[0] != 0u : (item[0] | item[1]) != 0u;
}
