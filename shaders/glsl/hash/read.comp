#version 460
// Dereference pass: out[i * ITEM_WORDS + w] = word w of the item named by handles[i]; zeros for
// HASH_MISS, HASH_INVALID and handles beyond the pool. One invocation per handle.
// Here `push.items` is the output. Driven by engine/hash/table.rs.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

#include "shared/hash_layout.h"
#include "hash/common.glsl"

void main() {
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    HashWords handles = HashWords(push.handles);
    HashWords out_words = HashWords(push.items);
    uint pool_slabs = push.blocks * HASH_SLABS_PER_BLOCK;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) for (;;) {
        uint handle = handles.w[i];
        uint slab = handle >> 5u;
        bool valid = handle != HASH_MISS && handle != HASH_INVALID && slab < pool_slabs;
        HashWords words = HashWords(valid ? hash_slab_address(push.super_blocks, slab) : push.items);
        for (uint w = 0u; w < ITEM_WORDS; ++w) {
            out_words.w[i * ITEM_WORDS + w] = valid ? words.w[hash_item_word(handle & 31u, w)] : 0u;
        }
        i += stride;
        if (i >= push.count) break;
    }
}
