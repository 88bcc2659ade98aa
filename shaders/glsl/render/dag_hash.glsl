// The hash DAG's child fetch (DAG_FORMAT_HASH, included by render/dag_formats.glsl): the live
// scene of the editor (engine/edit/gpu.rs) traversed in place, items read straight from its
// nine slab hash tables (one per item size 2..=10 words; item format: engine/edit/item.rs,
// docs/hash-dag.md; slab layout: shared/hash_layout.h, engine/hash/layout.rs). Twin of
// `edit_item` / `edit_item_read` in edit/common.glsl with the table variant a run-time value.
//
// A node handle is a child value of the editor (engine/edit/gpu.rs): a NodePtr
// `(words - 2) << 28 | slab << 5 | slot` (below HDAG_TAGGED), HDAG_FULL | material (the whole
// cube solid with one material) or HDAG_EMPTY. A full cube is traversed like a node whose
// children are all full: the traversal descends through it without reading memory, entering the
// same voxel at the same `t` as an svdag32 traversal of the same voxels.
//
// Inputs (engine/render/gpu.rs, `GpuRenderer::bind_hash_dag`):
//   push.dag_root      the root's child value (per dispatch: the editor's current root)
//   dag_info(i)        the binding's info block: HDAG_INFO_* below
// The colour index of a hit is the voxel's material (0 in geometry-only scenes): the renderer
// passes the palette as 16 raw colours, so `chunk_color(material)` is `palette[material]`.
#ifndef VOXDAG_RENDER_DAG_HASH_GLSL
#define VOXDAG_RENDER_DAG_HASH_GLSL

#include "shared/hash_layout.h"

// Info block words (`HASH_INFO_*` in engine/render/gpu.rs).
#define HDAG_INFO_VARIANT 0u
// Table t's super-block address table (u64, low word first) at words 2 + 2t, 2 + 2t + 1.
#define HDAG_INFO_TABLES 2u

// Child values (`VALUE_*` in engine/edit/gpu.rs, `EDIT_*` in edit/common.glsl).
#define HDAG_EMPTY 0xFFFFFFFFu
#define HDAG_FULL 0xF0000000u
#define HDAG_TAGGED 0x90000000u
#define HDAG_HANDLE_MASK 0x0FFFFFFFu

layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer HashDagAddressesRef {
    uint64_t a[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer HashDagWordsRef {
    uint w[];
};

bool hdag_is_ptr(uint v) {
    return v < HDAG_TAGGED;
}

// First word of the item storage of a slab (`SlabLayout`).
uint hdag_items_offset(uint variant) {
    if (variant == HASH_ATOMIC64) return 2u;
    if (variant == HASH_TICKET_BOARD) return 4u;
    if (variant == HASH_ACCEL32) return 4u + HASH_SLAB_SLOTS;
    return 4u + HASH_SLAB_SLOTS / 4u;
}

// An item located: its slab's address, slot, size and the table variant.
struct HdagItem {
    uint64_t slab;
    uint slot;
    uint words;
    uint variant;
};

// Where the item a NodePtr names lives: super-block table of its size, super block, slab.
HdagItem hdag_item(uint ptr) {
    HdagItem it;
    uint table = ptr >> 28u;
    uint handle = ptr & HDAG_HANDLE_MASK;
    uint slab = handle >> 5u;
    it.slot = handle & 31u;
    it.words = table + 2u;
    it.variant = dag_info(HDAG_INFO_VARIANT);
    uint64_t super_blocks = packUint2x32(
        uvec2(dag_info(HDAG_INFO_TABLES + 2u * table), dag_info(HDAG_INFO_TABLES + 2u * table + 1u)));
    uint64_t base = HashDagAddressesRef(super_blocks).a[slab / HASH_SLABS_PER_SUPER_BLOCK];
    // Words per slab (even: 64-bit prefixes stay 8-byte aligned).
    uint end = it.variant == HASH_ATOMIC64
                   ? 2u + 2u * HASH_SLAB_SLOTS + HASH_SLAB_SLOTS * (it.words - 2u)
                   : hdag_items_offset(it.variant) + HASH_SLAB_SLOTS * it.words;
    uint slab_words = (end + 1u) & ~1u;
    it.slab = base + uint64_t(HASH_SUPER_BLOCK_BITMASK_WORDS * 4u) +
              uint64_t(slab % HASH_SLABS_PER_SUPER_BLOCK) * uint64_t(slab_words * 4u);
    return it;
}

// Word w of a located item (Atomic64 keeps words 0 and 1 as the slot's 64-bit prefix).
uint hdag_word(HdagItem it, uint w) {
    uint items = hdag_items_offset(it.variant);
    uint at;
    if (it.variant == HASH_ATOMIC64) {
        at = w < 2u ? items + 2u * it.slot + w
                    : items + 2u * HASH_SLAB_SLOTS + it.slot * (it.words - 2u) + (w - 2u);
    } else {
        at = items + it.slot * it.words + w;
    }
    return HashDagWordsRef(it.slab).w[at];
}

void dag_root(uint root_level, out uint node, out uint xform) {
    node = push.dag_root;
    xform = 0u;
}

// Child mask of an inner node: the header's bits 0..8; a full cube has all eight children.
uint dag_inner_mask(uint node, uint xform, uint level) {
    if (hdag_is_ptr(node)) {
        return hdag_word(hdag_item(node), 0u) & 0xffu;
    }
    return node == HDAG_EMPTY ? 0u : 0xffu;
}

// Child c of an inner node: the word after the header for each present child before it, a
// material id where the header's full bit is set. A full cube's children are the full cube.
void dag_child(uint node, uint xform, uint mask, uint level, uint c, out uint child,
               out uint child_xform, out ivec3 shift, out uint at) {
    child_xform = 0u;
    shift = ivec3(0);
    at = 0u;
    if (!hdag_is_ptr(node)) {
        child = node;
        return;
    }
    HdagItem it = hdag_item(node);
    uint header = hdag_word(it, 0u);
    uint word = hdag_word(it, 1u + uint(bitCount(header & ((1u << c) - 1u) & 0xffu)));
    child = ((header >> (8u + c)) & 1u) != 0u ? (HDAG_FULL | word) : word;
}

// Sub-block s (2^3 voxels, one byte of the 64-bit mask) of a leaf.
uint dag_leaf_byte(uint node, uint xform, uint s) {
    if (!hdag_is_ptr(node)) {
        return 0xffu;
    }
    return (hdag_word(hdag_item(node), s >> 2u) >> (8u * (s & 3u))) & 0xffu;
}

// The material of the voxel at Morton code `code` of a leaf (the traversal's colour index):
// nibble `rank` of the words after the mask, rank = the leaf's voxels before `code`. Leaves of
// geometry-only scenes are exactly the two mask words (material 0); with materials every leaf
// has at least one material word.
uint dag_leaf_rank(uint node, uint xform, uint code) {
    if (!hdag_is_ptr(node)) {
        return node & 0xfu;
    }
    HdagItem it = hdag_item(node);
    if (it.words == 2u) {
        return 0u;
    }
    uint lo = hdag_word(it, 0u);
    uint rank = code < 32u
                    ? uint(bitCount(lo & ((1u << code) - 1u)))
                    : uint(bitCount(lo)) +
                          uint(bitCount(hdag_word(it, 1u) & ((1u << (code - 32u)) - 1u)));
    return (hdag_word(it, 2u + (rank >> 3u)) >> (4u * (rank & 7u))) & 0xfu;
}

// No voxel counts: the colour index is the material alone (dag_leaf_rank, DAG_HAS_LEAF_RANK).
#define DAG_HAS_VOXELS_BEFORE 1
uint64_t dag_voxels_before(uint node, uint xform, uint aux, uint level, uint c) {
    return 0ul;
}

#define DAG_HAS_LEAF_RANK 1

// The 64 voxel bits of a leaf (a full cube: all set), one item lookup (traverse.glsl keeps them).
#define DAG_HAS_LEAF_BITS 1
uvec2 dag_leaf_bits(uint node, uint xform) {
    if (!hdag_is_ptr(node)) {
        return uvec2(0xffffffffu);
    }
    HdagItem it = hdag_item(node);
    return uvec2(hdag_word(it, 0u), hdag_word(it, 1u));
}

#endif
