#version 460
// Lossless colour encoder, pass 3 of 3: one invocation per block writes the block's words at its
// offset (`write_block` in engine/attr/lossless.rs) and, for blocks 1.., its entry of the offset
// table that follows block 0. Every word of the chunk is written exactly once (padding bits
// zero), so the output needs no clearing. Driven by engine/attr_gpu/lossless.rs.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x_id = 0) in;

#include "attr/lossless_encode.glsl"

// Mirror of `WritePush` in engine/attr_gpu/lossless.rs (40 bytes).
#include "gen/attr.glsl"
// Members: `WritePush` in engine/attr_gpu/gpu_shared.rs.
layout(push_constant, std430) uniform Push { WRITE_PUSH_MEMBERS } push;

// LSB-first bit writer: bits gather in `acc` and leave as whole words.
LosslessEncWords out_words;
uint out_word;
uint acc;
uint fill;

void put_bits(uint value, uint width) {
    if (width == 0u) {
        return;
    }
    value &= (1u << width) - 1u; // width <= 24
    acc |= value << fill;
    if (fill + width >= 32u) {
        out_words.w[out_word++] = acc;
        // fill >= 8 here since width <= 24, so the shift is below 32.
        acc = value >> (32u - fill);
        fill = fill + width - 32u;
    } else {
        fill += width;
    }
}

void main() {
    uint blocks = (push.count + LOSSLESS_BLOCK_COLORS - 1u) / LOSSLESS_BLOCK_COLORS;
    uint b = gl_GlobalInvocationID.x;
    if (b >= blocks) {
        return;
    }
    out_words = LosslessEncWords(push.out_words);
    LosslessEncWords plans = LosslessEncWords(push.plans);
    uint64_t block_offset = LosslessEncOffsets(push.offsets).o[b];
    if (b > 0u) {
        uint at = plans.w[2] + 2u * (b - 1u); // the table starts where block 0 ends
        out_words.w[at] = uint(block_offset);
        out_words.w[at + 1u] = uint(block_offset >> 32);
    }

    uint first = b * LOSSLESS_BLOCK_COLORS;
    uint n = min(push.count - first, LOSSLESS_BLOCK_COLORS);
    lossless_load_block(push.colors, first, n, push.variant);
    uvec2 h = uvec2(plans.w[4u * b], plans.w[4u * b + 1u]);
    LosslessPlan p = lossless_plan_from_header(h, n);

    out_word = uint(block_offset);
    out_words.w[out_word++] = h.x;
    out_words.w[out_word++] = h.y;

    // References per colour, the run mask, and the set of distinct references.
    uint mask[4] = uint[4](0u, 0u, 0u, 0u);
    uint seen[16];
    for (uint k = 0u; k < 16u; k++) {
        seen[k] = 0u;
    }
    uint prev = 0xffffffffu;
    for (uint i = 0u; i < n; i++) {
        uint r = lossless_reference(lossless_unpack(lossless_block[i]) - p.minimum, p.shift);
        if (r != prev) {
            if (i > 0u) {
                mask[i >> 5u] |= 1u << (i & 31u);
            }
            prev = r;
        }
        seen[r >> 5u] |= 1u << (r & 31u);
    }
    if (p.runs > 1u) {
        for (uint k = 0u; k < lossless_plan_mask_words(p); k++) {
            out_words.w[out_word++] = mask[k];
        }
    }

    acc = 0u;
    fill = 0u;
    if (p.indexed) {
        // Palette: distinct references ascending; each run stores its reference's rank.
        for (uint k = 0u; k < 16u; k++) {
            uint bits = seen[k];
            while (bits != 0u) {
                put_bits(32u * k + uint(findLSB(bits)), 9u);
                bits &= bits - 1u;
            }
        }
        uint index_bits = lossless_index_bits(p);
        prev = 0xffffffffu;
        for (uint i = 0u; i < n; i++) {
            uint r = lossless_reference(lossless_unpack(lossless_block[i]) - p.minimum, p.shift);
            if (r != prev) {
                uint rank = bitCount(seen[r >> 5u] & ((1u << (r & 31u)) - 1u));
                for (uint k = 0u; k < (r >> 5u); k++) {
                    rank += bitCount(seen[k]);
                }
                put_bits(rank, index_bits);
                prev = r;
            }
        }
    } else {
        prev = 0xffffffffu;
        for (uint i = 0u; i < n; i++) {
            uint r = lossless_reference(lossless_unpack(lossless_block[i]) - p.minimum, p.shift);
            if (r != prev) {
                put_bits(r, 9u);
                prev = r;
            }
        }
    }
    uvec3 low = (uvec3(1u) << p.shift) - 1u;
    uint width = p.shift.x + p.shift.y + p.shift.z;
    for (uint i = 0u; i < n; i++) {
        uvec3 v = (lossless_unpack(lossless_block[i]) - p.minimum) & low;
        put_bits(v.x | (v.y << p.shift.x) | (v.z << (p.shift.x + p.shift.y)), width);
    }
    if (fill > 0u) {
        out_words.w[out_word++] = acc;
    }
}
