// Block planning of the lossless colour encoder, shared by `lossless_plan.comp` and
// `lossless_write.comp`: the GLSL twin of `plan_block` / `plan_with_shift` in
// engine/attr/lossless.rs, with the same iteration order and tie-breaking so the GPU writes the
// same words as the CPU. One invocation encodes one block of up to 128 colours.
//
// The includer enables GL_EXT_buffer_reference and GL_EXT_shader_explicit_arithmetic_types_int64.
#ifndef VOXDAG_ATTR_LOSSLESS_ENCODE_GLSL
#define VOXDAG_ATTR_LOSSLESS_ENCODE_GLSL

#define LOSSLESS_BLOCK_COLORS 128u
// Extra shifts tried per block: `attr::lossless::EXTRA_SHIFTS`, set by the host (constant 1).
layout(constant_id = 1) const uint LOSSLESS_EXTRA_SHIFTS = 4u;

layout(buffer_reference, std430, buffer_reference_align = 4) buffer LosslessEncWords {
    uint w[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) buffer LosslessEncOffsets {
    uint64_t o[];
};

// A block's choices (its two header words) and its colour count.
struct LosslessPlan {
    uint variant;
    uint colors;
    uvec3 minimum;
    uvec3 shift;
    uint runs;
    uint palette;
    bool indexed;
};

uint lossless_bit_length(uint v) {
    return uint(findMSB(v) + 1);
}

// Coded channels of an RGBA8 colour (`LosslessVariant::to_channels`), packed r | g << 8 | b << 16.
uint lossless_channels(uint color, uint variant) {
    uvec3 c = uvec3(color & 0xffu, (color >> 8u) & 0xffu, (color >> 16u) & 0xffu);
    if (variant == 1u) {
        c = (c * uvec3(31u, 63u, 31u) + 127u) / 255u;
    }
    return c.x | (c.y << 8u) | (c.z << 16u);
}

uvec3 lossless_unpack(uint packed) {
    return uvec3(packed & 0xffu, (packed >> 8u) & 0xffu, (packed >> 16u) & 0xffu);
}

uint lossless_reference(uvec3 n, uvec3 shift) {
    uvec3 r = n >> shift;
    return r.x | (r.y << 3u) | (r.z << 6u);
}

uint lossless_index_bits(LosslessPlan p) {
    return p.indexed ? lossless_bit_length(p.palette - 1u) : 0u;
}

uint lossless_stream_bits(LosslessPlan p) {
    return p.palette * 9u + p.runs * lossless_index_bits(p)
        + p.colors * (p.shift.x + p.shift.y + p.shift.z);
}

uint lossless_plan_mask_words(LosslessPlan p) {
    return p.runs > 1u ? (p.colors + 31u) / 32u : 0u;
}

uint lossless_block_words(LosslessPlan p) {
    return 2u + lossless_plan_mask_words(p) + (lossless_stream_bits(p) + 31u) / 32u;
}

uvec2 lossless_header(LosslessPlan p) {
    uint a = p.minimum.x | (p.minimum.y << 8u) | (p.minimum.z << 16u);
    uint b = p.shift.x | (p.shift.y << 4u) | (p.shift.z << 8u) | ((p.runs - 1u) << 12u)
        | ((p.palette - 1u) << 19u) | ((p.indexed ? 1u : 0u) << 26u)
        | (uint(max(int(lossless_plan_mask_words(p)) - 1, 0)) << 27u) | (p.variant << 29u);
    return uvec2(a, b);
}

LosslessPlan lossless_plan_from_header(uvec2 h, uint n) {
    LosslessPlan p;
    p.variant = (h.y >> 29u) & 1u;
    p.colors = n;
    p.minimum = uvec3(h.x & 0xffu, (h.x >> 8u) & 0xffu, (h.x >> 16u) & 0xffu);
    p.shift = uvec3(h.y & 15u, (h.y >> 4u) & 15u, (h.y >> 8u) & 15u);
    p.runs = ((h.y >> 12u) & 127u) + 1u;
    p.palette = ((h.y >> 19u) & 127u) + 1u;
    p.indexed = ((h.y >> 26u) & 1u) != 0u;
    return p;
}

// The block's coded channels (packed), loaded once by the invocation.
uint lossless_block[LOSSLESS_BLOCK_COLORS];

void lossless_load_block(uint64_t colors_address, uint first, uint n, uint variant) {
    LosslessEncWords colors = LosslessEncWords(colors_address);
    for (uint i = 0u; i < n; i++) {
        lossless_block[i] = lossless_channels(colors.w[first + i], variant);
    }
}

LosslessPlan lossless_plan_with_shift(uint n, uint variant, uvec3 minimum, uvec3 shift) {
    uint seen[16];
    for (uint k = 0u; k < 16u; k++) {
        seen[k] = 0u;
    }
    uint runs = 0u;
    uint prev = 0xffffffffu;
    for (uint i = 0u; i < n; i++) {
        uint r = lossless_reference(lossless_unpack(lossless_block[i]) - minimum, shift);
        if (r != prev) {
            runs++;
            prev = r;
        }
        seen[r >> 5u] |= 1u << (r & 31u);
    }
    uint palette = 0u;
    for (uint k = 0u; k < 16u; k++) {
        palette += bitCount(seen[k]);
    }
    uint direct_bits = runs * 9u;
    uint indexed_bits = palette * 9u + runs * lossless_bit_length(palette - 1u);
    LosslessPlan p;
    p.variant = variant;
    p.colors = n;
    p.minimum = minimum;
    p.shift = shift;
    p.runs = runs;
    p.indexed = indexed_bits < direct_bits;
    p.palette = p.indexed ? palette : runs;
    return p;
}

// `plan_block`: minimal 3-bit-reference shifts plus 0..LOSSLESS_EXTRA_SHIFTS, first fewest words.
LosslessPlan lossless_plan_block(uint n, uint variant) {
    uvec3 lo = uvec3(255u);
    uvec3 hi = uvec3(0u);
    for (uint i = 0u; i < n; i++) {
        uvec3 c = lossless_unpack(lossless_block[i]);
        lo = min(lo, c);
        hi = max(hi, c);
    }
    uvec3 range_bits = uvec3(lossless_bit_length(hi.x - lo.x), lossless_bit_length(hi.y - lo.y),
                             lossless_bit_length(hi.z - lo.z));
    uvec3 base = uvec3(max(ivec3(range_bits) - 3, ivec3(0)));
    LosslessPlan best = lossless_plan_with_shift(n, variant, lo, base);
    uint best_words = lossless_block_words(best);
    for (uint extra = 1u; extra < LOSSLESS_EXTRA_SHIFTS; extra++) {
        LosslessPlan p = lossless_plan_with_shift(n, variant, lo, min(base + extra, range_bits));
        uint words = lossless_block_words(p);
        if (words < best_words) {
            best = p;
            best_words = words;
        }
    }
    return best;
}

#endif // VOXDAG_ATTR_LOSSLESS_ENCODE_GLSL
