// GPU hash DAG editing: child values, reading items of the nine per-size tables, tool tests.
// Twin of engine/edit/gpu.rs (value encoding) and engine/edit/item.rs (item format).
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_control_flow_attributes : require

#include "shared/hash_layout.h"
#include "gen/edit.glsl"

// The pass's parameters: push constants, or (EDIT_PARAMS_IN_MEMORY, a shader that runs the
// passes of several levels: edit/merge_small_levels.comp, edit/traverse_small_levels.comp) a
// variable the includer sets per level from the levels' records (edit_record).
struct EditParams { EDIT_PUSH_MEMBERS };
#ifdef EDIT_PARAMS_IN_MEMORY
EditParams push;
// The chains' records as uvec4 texels (binding 0): inside the chains' level loop lavapipe
// reads memory through an address one lane at a time, a loop per field, but fetches a texel
// for all lanes at once (docs/gpu.md, "Records read as texels").
layout(set = 0, binding = 0) uniform usamplerBuffer edit_records;

// The EditParams whose record starts at texel `at`.
EditParams edit_record(uint at) {
    uvec4 t[EDIT_PUSH_UVEC4S];
    [[unroll]] for (uint k = 0u; k < EDIT_PUSH_UVEC4S; ++k) {
        t[k] = texelFetch(edit_records, int(at + k));
    }
    return EditParams(EDIT_PUSH_FROM_UVEC4S(t));
}
#else
layout(push_constant, std430) uniform Push { EDIT_PUSH_MEMBERS } push;
#endif

layout(buffer_reference, std430, buffer_reference_align = 4) coherent buffer Words {
    uint w[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) buffer Addresses {
    uint64_t a[];
};
// Coherent: edit/traverse_small_levels.comp reads a level's entries that other invocations of
// its workgroup appended before its barrier.
layout(buffer_reference, std430, buffer_reference_align = 16) coherent buffer Entries {
    uvec4 e[];
};

// A child value (one u32): a NodePtr (`(words - 2) << 28 | handle`, below 0x90000000), or one
// of the tagged values below.
#define EDIT_EMPTY 0xFFFFFFFFu
#define EDIT_FULL 0xF0000000u     // | material
#define EDIT_TEMP 0x90000000u     // | index into the level below's results
#define EDIT_PENDING 0xE0000000u  // | size table index: item appended, handle not known yet
#define EDIT_TAG_MASK 0xF0000000u
#define EDIT_INDEX_MASK 0x0FFFFFFFu

#define EDIT_FLAG_LEAVES 1u
#define EDIT_FLAG_RESULT_INDEX 8u
// The tool of traverse / leaves / fill passes: flags >> EDIT_TOOL_SHIFT & 7 (engine/edit/gpu.rs
// `ToolKind`).
#define EDIT_TOOL_SHIFT 4u
#define EDIT_TOOL_ADD 0u
#define EDIT_TOOL_REMOVE 1u
#define EDIT_TOOL_PAINT 2u
#define EDIT_TOOL_FILL 3u
#define EDIT_TOOL_COPY 4u

// The tool parameter buffer (push.src2 of leaves and the fill passes, u32 / f32 words; twin of
// `tool_params` in engine/edit/gpu.rs): the fill box (min corner, dims, start voxel index),
// the root level, and the copy's source anchor, destination anchor, source cube (centre,
// half-size) and inverse transform (flag, 9 floats by rows).
#define EDIT_P_MIN 0u
#define EDIT_P_DIMS 3u
#define EDIT_P_START 6u
#define EDIT_P_ROOT_LEVEL 7u
#define EDIT_P_SOURCE 8u
#define EDIT_P_DEST 11u
#define EDIT_P_SRC_CENTER 14u
#define EDIT_P_SRC_RADIUS 17u
#define EDIT_P_HAS_INVERSE 18u
#define EDIT_P_INVERSE 19u

// The per-level address buffer (push.tables of build_items / resolve): per size table s
// (0..9) its items; one slot per node (the index of its item in its size's buffer); every
// size's dedup representatives and handles, size s from word s * stride (the stride a u64
// word: 0 where the level has one possible size), so that a child's size gives them by
// arithmetic rather than by a load of a per-size address; the level below's address buffer
// when its results are left pending for build_items to resolve (0: resolved by its own
// pass), and the counter of nodes left without a handle.
#define EDIT_LEVEL_ITEMS 0u
#define EDIT_LEVEL_SLOTS 9u
#define EDIT_LEVEL_REPS 10u
#define EDIT_LEVEL_HANDLES 11u
#define EDIT_LEVEL_STRIDE 12u
#define EDIT_LEVEL_BELOW 13u
#define EDIT_LEVEL_MISSING 14u

#define EDIT_SHAPE_SPHERE 0u
#define EDIT_SHAPE_CUBE 1u

bool edit_is_ptr(uint v) {
    return v < EDIT_TEMP;
}

bool edit_is_full(uint v) {
    return (v & 0xFFFFFFF0u) == EDIT_FULL;
}

// Where a level's representatives and handles are (read once per invocation: on lavapipe a
// load through a buffer address is a loop over the SIMD lanes, uniform or not).
struct EditLevelHandles {
    uint64_t reps;
    uint64_t handles;
    uint stride;
};

EditLevelHandles edit_level_handles(Addresses level) {
    return EditLevelHandles(level.a[EDIT_LEVEL_REPS], level.a[EDIT_LEVEL_HANDLES],
                            uint(level.a[EDIT_LEVEL_STRIDE]));
}

// The NodePtr of a pending result r (EDIT_PENDING | size) whose item's representative has
// `handle`, or r where that item has none (HASH_MISS / HASH_INVALID, at or above 2^28).
uint edit_resolved(uint r, uint handle) {
    return handle >= (1u << 28u) ? r : (r & 15u) << 28u | handle;
}

// The NodePtr of a pending result r (EDIT_PENDING | size) whose item is entry `index` of its
// size's items in `level`: the handle of the item's representative, once the level's inserts
// ran. An item left without a handle (a pool ran out) gives r back: the caller counts it as
// missing and keeps r.
uint edit_resolve_slot(EditLevelHandles level, uint index, uint r) {
    uint base = (r & 15u) * level.stride;
    uint rep = Words(level.reps).w[base + index];
    return edit_resolved(r, Words(level.handles).w[base + rep]);
}

// ---- reading items (twin of hash/common.glsl with the item size a run-time value) ----

uint edit_items_offset() {
    if (push.variant == HASH_ATOMIC64) return 2u;
    if (push.variant == HASH_TICKET_BOARD) return 4u;
    if (push.variant == HASH_ACCEL32) return 4u + HASH_SLAB_SLOTS;
    return 4u + HASH_SLAB_SLOTS / 4u;
}

uint edit_slab_words(uint words) {
    uint end = push.variant == HASH_ATOMIC64
        ? 2u + 2u * HASH_SLAB_SLOTS + HASH_SLAB_SLOTS * (words - 2u)
        : edit_items_offset() + HASH_SLAB_SLOTS * words;
    return (end + 1u) & ~1u;
}

uint edit_item_word(uint words, uint slot, uint w) {
    uint items = edit_items_offset();
    if (push.variant == HASH_ATOMIC64) {
        return w < 2u ? items + 2u * slot + w
                      : items + 2u * HASH_SLAB_SLOTS + slot * (words - 2u) + (w - 2u);
    }
    return items + slot * words + w;
}

// Where the item a NodePtr names lives: its slab's address (two dependent loads to find), its
// size and its slot. A pass that reads several words of one item finds it once.
struct EditItem {
    uint64_t slab;
    uint words;
    uint slot;
};

// The item a NodePtr names (push.tables: the nine super-block tables).
EditItem edit_item(uint ptr) {
    uint table = ptr >> 28u;
    uint handle = ptr & EDIT_INDEX_MASK;
    uint slab = handle >> 5u;
    EditItem item;
    item.words = table + 2u;
    item.slot = handle & 31u;
    uint64_t base = Addresses(Addresses(push.tables).a[table]).a[slab / HASH_SLABS_PER_SUPER_BLOCK];
    item.slab = base + uint64_t(HASH_SUPER_BLOCK_BITMASK_WORDS * 4u)
              + uint64_t(slab % HASH_SLABS_PER_SUPER_BLOCK) * uint64_t(edit_slab_words(item.words) * 4u);
    return item;
}

// Word w of an item.
uint edit_item_read(EditItem item, uint w) {
    return Words(item.slab).w[edit_item_word(item.words, item.slot, w)];
}

// The eight children of a stored node value (pointer, full or empty) at an inner level. The
// loops over the children are unrolled wherever an array holds them (here and in the passes
// that call this): an array indexed by a loop counter is a loop over the SIMD lanes on
// lavapipe at every access (docs/editing-gpu.md, "Speed, round 8"). Includers enable
// GL_EXT_control_flow_attributes.
void edit_children(uint v, out uint children[8]) {
    if (!edit_is_ptr(v)) {
        [[unroll]] for (uint o = 0u; o < 8u; ++o) children[o] = v;
        return;
    }
    EditItem node = edit_item(v);
    uint header = edit_item_read(node, 0u);
    uint next = 1u;
    [[unroll]] for (uint o = 0u; o < 8u; ++o) {
        if ((header >> o & 1u) == 0u) {
            children[o] = EDIT_EMPTY;
        } else {
            uint word = edit_item_read(node, next++);
            children[o] = (header >> (8u + o) & 1u) != 0u ? EDIT_FULL | word : word;
        }
    }
}

// ---- tools (voxel-centre inclusion, exactly as engine/edit/tool.rs's `in_sphere` / `in_cube`) ----

// Records of the pass: push.count, or the count an earlier pass left at push.count_at (bounded by
// push.count, the capacity the host sized the buffers for).
uint edit_count() {
    if (push.count_at == 0ul) return push.count;
    return min(Words(push.count_at).w[0], push.count);
}

// The traverse and leaves pipelines are made once per tool with the tool as specialization
// constant 0 (engine/edit/gpu.rs `ToolPipelines`): lavapipe runs every branch of a shader,
// masked, so a pipeline that knows its tool leaves the other tools' code out. Other passes keep
// the default and read the tool from the flags.
// EDIT_SPEC_ID_BASE moves both constants' ids past those of the hash passes where a shader
// runs both (edit/merge_small_levels.comp).
#ifndef EDIT_SPEC_ID_BASE
#define EDIT_SPEC_ID_BASE 0
#endif
#define EDIT_TOOL_FROM_FLAGS 7u
layout(constant_id = EDIT_SPEC_ID_BASE) const uint EDIT_SPEC_TOOL = EDIT_TOOL_FROM_FLAGS;

uint edit_tool() {
    return EDIT_SPEC_TOOL != EDIT_TOOL_FROM_FLAGS ? EDIT_SPEC_TOOL : push.flags >> EDIT_TOOL_SHIFT & 7u;
}

// Whether the scene's leaves carry materials (one nibble per voxel): specialization constant 1,
// fixed for a hash DAG's lifetime and given to every edit pipeline (engine/edit/gpu.rs), so a
// geometry-only scene's passes leave the material code out (lavapipe would run it, masked, for
// every voxel: half the leaves pass's time).
layout(constant_id = EDIT_SPEC_ID_BASE + 1) const uint EDIT_SPEC_MATERIALS = 0u;

bool edit_materials() {
    return EDIT_SPEC_MATERIALS != 0u;
}

// `precise`: no fused multiply-add, so the CPU twin's f32 arithmetic gives the same answer bit
// for bit.
bool edit_in_cube(vec3 c, float r, uvec3 p) {
    precise vec3 centre = vec3(p) + 0.5;
    precise vec3 lo = c - r;
    precise vec3 hi = c + r;
    return all(lessThanEqual(lo, centre)) && all(lessThanEqual(centre, hi));
}

bool edit_in_sphere(vec3 c, float r, uvec3 p) {
    precise vec3 d = (vec3(p) + 0.5) - c;
    precise float d2 = d.x * d.x + d.y * d.y + d.z * d.z;
    precise float r2 = r * r;
    return d2 <= r2;
}

// Whether the voxel with integer corner p is inside the tool's region (push.shape, push.tool).
bool edit_voxel_inside(uvec3 p) {
    if (push.shape == EDIT_SHAPE_CUBE) return edit_in_cube(push.tool.xyz, push.tool.w, p);
    return edit_in_sphere(push.tool.xyz, push.tool.w, p);
}

// Whether every voxel of the cube [p, p + side) is inside: the computed distance grows with
// every |d| component, so the voxel whose centre is farthest per axis decides.
bool edit_cube_all_inside(uvec3 p, uint side) {
    uvec3 last = p + uvec3(side - 1u);
    if (push.shape == EDIT_SHAPE_CUBE) {
        // Per axis the inside voxels form an interval: both corners inside is enough.
        return edit_voxel_inside(p) && edit_voxel_inside(last);
    }
    precise vec3 dlo = (vec3(p) + 0.5) - push.tool.xyz;
    precise vec3 dhi = (vec3(last) + 0.5) - push.tool.xyz;
    uvec3 far = p;
    [[unroll]] for (int a = 0; a < 3; ++a) {
        if (abs(dhi[a]) > abs(dlo[a])) far[a] = last[a];
    }
    return edit_voxel_inside(far);
}

// Whether no voxel of the cube can be inside (conservative by one voxel of margin: a cube
// near the boundary is subdivided, never wrongly kept).
bool edit_cube_all_outside(uvec3 p, uint side) {
    vec3 lo = vec3(p);
    vec3 hi = vec3(p + uvec3(side));
    vec3 c = push.tool.xyz;
    float r = push.tool.w + 1.0;
    if (push.shape == EDIT_SHAPE_CUBE) {
        return any(lessThan(hi, c - r)) || any(greaterThan(lo, c + r));
    }
    vec3 d = max(max(lo - c, c - hi), vec3(0.0));
    return dot(d, d) > r * r;
}

// ---- reading the scene before the edit ----

// Leaf voxels 8g..8g+7 (a 2^3 sub-block) of the masks lo (voxels 0-31) and hi (32-63).
uint leaf_byte(uint lo, uint hi, uint g) {
    return ((g < 4u ? lo : hi) >> (8u * (g & 3u))) & 0xffu;
}

// Bit b of a leaf byte moved to bit 4b (bit 0 of voxel b's material nibble).
uint leaf_byte_nibbles(uint byte) {
    uint s = (byte | (byte << 12u)) & 0x000F000Fu;
    s = (s | (s << 6u)) & 0x03030303u;
    return (s | (s << 3u)) & 0x11111111u;
}

// State of voxel p (grid coordinates) under the stored value v of a level-`level` cube that
// contains it: EDIT_EMPTY, or the voxel's material.
uint edit_lookup(uint v, uint level, uvec3 p) {
    bool materials = edit_materials();
    for (;;) {
        if (v == EDIT_EMPTY) return EDIT_EMPTY;
        if (edit_is_full(v)) return v & 15u;
        if (level == 0u) {
            // Bit = Morton code of the voxel inside its 4^3 leaf.
            uvec3 l = p & 3u;
            uint bit = (l.x & 1u) | (l.y & 1u) << 1u | (l.z & 1u) << 2u
                     | (l.x >> 1u) << 3u | (l.y >> 1u) << 4u | (l.z >> 1u) << 5u;
            EditItem leaf = edit_item(v);
            uint lo = edit_item_read(leaf, 0u);
            uint hi = edit_item_read(leaf, 1u);
            uint word = bit < 32u ? lo : hi;
            if ((word >> (bit & 31u) & 1u) == 0u) return EDIT_EMPTY;
            if (!materials) return 0u;
            // Materials are packed by rank among the set bits (item.rs `Leaf`).
            uint rank = bit < 32u ? bitCount(lo & ((1u << bit) - 1u))
                                  : bitCount(lo) + bitCount(hi & ((1u << (bit - 32u)) - 1u));
            return edit_item_read(leaf, 2u + rank / 8u) >> (4u * (rank % 8u)) & 15u;
        }
        uint s = level + 1u;
        uint o = (p.x >> s & 1u) | (p.y >> s & 1u) << 1u | (p.z >> s & 1u) << 2u;
        EditItem node = edit_item(v);
        uint header = edit_item_read(node, 0u);
        if ((header >> o & 1u) == 0u) return EDIT_EMPTY;
        uint word = edit_item_read(node, 1u + bitCount(header & ((1u << o) - 1u) & 0xFFu));
        v = (header >> (8u + o) & 1u) != 0u ? EDIT_FULL | word : word;
        level--;
    }
    return EDIT_EMPTY;
}

uint edit_param(uint at) {
    return Words(push.src2).w[at];
}

float edit_param_f(uint at) {
    return uintBitsToFloat(Words(push.src2).w[at]);
}

vec3 edit_param_vec3(uint at) {
    return vec3(edit_param_f(at), edit_param_f(at + 1u), edit_param_f(at + 2u));
}

// Bit i of a bitmap (u32 words).
bool edit_bit(uint64_t bitmap, uint i) {
    return (Words(bitmap).w[i >> 5u] >> (i & 31u) & 1u) != 0u;
}

// Index of voxel p in the fill box's bitmap (x fastest), or 0xFFFFFFFF outside the box.
uint edit_fill_index(uvec3 p) {
    uvec3 lo = uvec3(edit_param(EDIT_P_MIN), edit_param(EDIT_P_MIN + 1u), edit_param(EDIT_P_MIN + 2u));
    uvec3 dims = uvec3(edit_param(EDIT_P_DIMS), edit_param(EDIT_P_DIMS + 1u), edit_param(EDIT_P_DIMS + 2u));
    if (any(lessThan(p, lo)) || any(greaterThanEqual(p - lo, dims))) return 0xFFFFFFFFu;
    uvec3 d = p - lo;
    return d.x + dims.x * (d.y + dims.y * d.z);
}

// The copy's source voxel state for destination voxel p (tool.rs `CopyRegion::source_voxel`
// with its f32 operation order, then the source cube test and a lookup in the pre-edit root).
uint edit_copy_source(uvec3 p) {
    uint root_level = edit_param(EDIT_P_ROOT_LEVEL);
    precise vec3 rel = (vec3(p) + 0.5) - edit_param_vec3(EDIT_P_DEST);
    if (edit_param(EDIT_P_HAS_INVERSE) != 0u) {
        precise vec3 t;
        [[unroll]] for (uint r = 0u; r < 3u; ++r) {
            uint at = EDIT_P_INVERSE + 3u * r;
            t[r] = edit_param_f(at) * rel.x + edit_param_f(at + 1u) * rel.y + edit_param_f(at + 2u) * rel.z;
        }
        rel = t;
    }
    precise vec3 s = floor(edit_param_vec3(EDIT_P_SOURCE) + rel);
    float side = float(4u << root_level);
    if (any(lessThan(s, vec3(0.0))) || any(greaterThanEqual(s, vec3(side)))) return EDIT_EMPTY;
    uvec3 sv = uvec3(s);
    if (!edit_in_cube(edit_param_vec3(EDIT_P_SRC_CENTER), edit_param_f(EDIT_P_SRC_RADIUS), sv)) {
        return EDIT_EMPTY;
    }
    return edit_lookup(push.root, root_level, sv);
}

// The new state of voxel p (EDIT_EMPTY or a material) whose state before the edit is `old`:
// tool.rs `Edit::voxel`. Fill reads its flooded bitmap at push.dst2.
uint edit_new_voxel(uvec3 p, uint old) {
    uint tool = edit_tool();
    if (tool == EDIT_TOOL_ADD) return edit_voxel_inside(p) ? push.material : old;
    if (tool == EDIT_TOOL_REMOVE) return edit_voxel_inside(p) ? EDIT_EMPTY : old;
    if (tool == EDIT_TOOL_PAINT) return old != EDIT_EMPTY && edit_voxel_inside(p) ? push.material : old;
    // Fill and copy only change empty voxels.
    if (old != EDIT_EMPTY) return old;
    if (tool == EDIT_TOOL_FILL) {
        uint i = edit_fill_index(p);
        return i != 0xFFFFFFFFu && edit_bit(push.dst2, i) ? push.material : old;
    }
    if (!edit_voxel_inside(p)) return EDIT_EMPTY;
    return edit_copy_source(p);
}
