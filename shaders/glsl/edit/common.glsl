// GPU hash DAG editing: child values, reading items of the nine per-size tables, tool tests.
// Twin of engine/edit/gpu.rs (value encoding) and engine/edit/item.rs (item format).
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

#include "shared/hash_layout.h"
#include "gen/edit.glsl"

layout(push_constant, std430) uniform Push { EDIT_PUSH_MEMBERS } push;

layout(buffer_reference, std430, buffer_reference_align = 4) coherent buffer Words {
    uint w[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) buffer Addresses {
    uint64_t a[];
};
layout(buffer_reference, std430, buffer_reference_align = 16) buffer Entries {
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
#define EDIT_FLAG_MATERIALS 2u
#define EDIT_FLAG_REMOVE 4u
#define EDIT_FLAG_RESULT_INDEX 8u

// The per-level address buffer (push.tables of build_items / resolve): per size table s
// (0..9) its items, its dedup representatives and its handles, and one slot per node (the
// index of its item in its size's buffer).
#define EDIT_LEVEL_ITEMS 0u
#define EDIT_LEVEL_SLOTS 9u
#define EDIT_LEVEL_REPS 10u
#define EDIT_LEVEL_HANDLES 19u

#define EDIT_SHAPE_SPHERE 0u
#define EDIT_SHAPE_CUBE 1u

bool edit_is_ptr(uint v) {
    return v < EDIT_TEMP;
}

bool edit_is_full(uint v) {
    return (v & 0xFFFFFFF0u) == EDIT_FULL;
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

// Word w of the item a NodePtr names (push.tables: the nine super-block tables).
uint edit_read(uint ptr, uint w) {
    uint table = ptr >> 28u;
    uint words = table + 2u;
    uint handle = ptr & EDIT_INDEX_MASK;
    uint slab = handle >> 5u;
    uint64_t base = Addresses(Addresses(push.tables).a[table]).a[slab / HASH_SLABS_PER_SUPER_BLOCK];
    uint64_t at = base + uint64_t(HASH_SUPER_BLOCK_BITMASK_WORDS * 4u)
                + uint64_t(slab % HASH_SLABS_PER_SUPER_BLOCK) * uint64_t(edit_slab_words(words) * 4u);
    return Words(at).w[edit_item_word(words, handle & 31u, w)];
}

// The eight children of a stored node value (pointer, full or empty) at an inner level.
void edit_children(uint v, out uint children[8]) {
    if (!edit_is_ptr(v)) {
        for (uint o = 0u; o < 8u; ++o) children[o] = v;
        return;
    }
    uint header = edit_read(v, 0u);
    uint next = 1u;
    for (uint o = 0u; o < 8u; ++o) {
        if ((header >> o & 1u) == 0u) {
            children[o] = EDIT_EMPTY;
        } else {
            uint word = edit_read(v, next++);
            children[o] = (header >> (8u + o) & 1u) != 0u ? EDIT_FULL | word : word;
        }
    }
}

// ---- tools (voxel-centre inclusion, exactly as engine/edit/tool.rs's `in_sphere` / `in_cube`) ----

// Whether the voxel with integer corner p is inside the tool. `precise`: no fused
// multiply-add, so the CPU twin's f32 arithmetic gives the same answer bit for bit.
bool edit_voxel_inside(uvec3 p) {
    if (push.shape == EDIT_SHAPE_CUBE) {
        precise vec3 centre = vec3(p) + 0.5;
        precise vec3 lo = push.tool.xyz - push.tool.w;
        precise vec3 hi = push.tool.xyz + push.tool.w;
        return all(lessThanEqual(lo, centre)) && all(lessThanEqual(centre, hi));
    }
    precise vec3 d = (vec3(p) + 0.5) - push.tool.xyz;
    precise float d2 = d.x * d.x + d.y * d.y + d.z * d.z;
    precise float r2 = push.tool.w * push.tool.w;
    return d2 <= r2;
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
    for (int a = 0; a < 3; ++a) {
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
