// Random-access decoder of the lossless colour codec: the GLSL twin of
// `attr::lossless::decode` (engine/attr/lossless.rs; layout in docs/colors-lossless.md).
//
//   uint lossless_color(uint64_t chunk_words_address, uint index)
//
// returns colour `index` of the encoded chunk at `chunk_words_address` as an opaque RGBA8 word
// (r | g << 8 | b << 16 | 0xff << 24). No validation: the host validated the chunk
// (`attr::lossless::decode_all`) before uploading it. The includer enables
// GL_EXT_buffer_reference and GL_EXT_shader_explicit_arithmetic_types_int64.
#ifndef VOXDAG_ATTR_LOSSLESS_GLSL
#define VOXDAG_ATTR_LOSSLESS_GLSL

layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer LosslessWords {
    uint w[];
};

// `LosslessVariant::Rgb565` in the low byte of the chunk header.
#define LOSSLESS_VARIANT_565 1u

// `width` (<= 24) bits LSB-first at bit `pos` of the words at `words`.
uint lossless_read_bits(LosslessWords words, uint pos, uint width) {
    if (width == 0u) {
        return 0u;
    }
    uint w = pos >> 5u;
    uint bit = pos & 31u;
    uint v = words.w[w] >> bit;
    if (bit + width > 32u) {
        v |= words.w[w + 1u] << (32u - bit);
    }
    return v & ((1u << width) - 1u);
}

uint lossless_color(uint64_t chunk_words_address, uint index) {
    LosslessWords chunk = LosslessWords(chunk_words_address);
    uint variant = chunk.w[0] & 0xffu;
    uint block = index >> 7u;
    uint i = index & 127u;
    uint64_t block_offset = uint64_t(chunk.w[1u + 2u * block])
        | (uint64_t(chunk.w[2u + 2u * block]) << 32);
    uint64_t block_address = chunk_words_address + block_offset * 4ul;
    LosslessWords blk = LosslessWords(block_address);

    uint head_a = blk.w[0];
    uint head_b = blk.w[1];
    uvec3 minimum = uvec3(head_a & 0xffu, (head_a >> 8u) & 0xffu, (head_a >> 16u) & 0xffu);
    uvec3 shift = uvec3(head_b & 15u, (head_b >> 4u) & 15u, (head_b >> 8u) & 15u);
    uint runs = ((head_b >> 12u) & 127u) + 1u;
    uint palette = ((head_b >> 19u) & 127u) + 1u;
    bool indexed = ((head_b >> 26u) & 1u) != 0u;

    // Run of colour i: set mask bits at positions 0..=i (bit 0 is always clear).
    uint run = 0u;
    uint stream_word = 2u;
    if (runs > 1u) {
        uint mw = i >> 5u;
        for (uint k = 0u; k < mw; k++) {
            run += bitCount(blk.w[2u + k]);
        }
        uint bit = i & 31u;
        uint keep = bit == 31u ? 0xffffffffu : ((2u << bit) - 1u);
        run += bitCount(blk.w[2u + mw] & keep);
        stream_word = 6u;
    }
    LosslessWords stream = LosslessWords(block_address + uint64_t(stream_word) * 4ul);

    uint palette_bits = palette * 9u;
    uint index_bits = indexed ? uint(findMSB(palette - 1u) + 1) : 0u;
    uint entry = indexed ? lossless_read_bits(stream, palette_bits + run * index_bits, index_bits)
                         : run;
    uint ref_bits = lossless_read_bits(stream, entry * 9u, 9u);
    uint width = shift.x + shift.y + shift.z;
    uint offset = lossless_read_bits(stream, palette_bits + runs * index_bits + i * width, width);

    uvec3 reference = uvec3(ref_bits & 7u, (ref_bits >> 3u) & 7u, (ref_bits >> 6u) & 7u);
    uvec3 low = uvec3(offset, offset >> shift.x, offset >> (shift.x + shift.y))
        & ((uvec3(1u) << shift) - 1u);
    uvec3 c = minimum + (reference << shift) + low;
    if (variant == LOSSLESS_VARIANT_565) {
        // Bit replication to 8 bits (`attr::lossless::expand`).
        c = uvec3((c.x << 3u) | (c.x >> 2u), (c.y << 2u) | (c.y >> 4u), (c.z << 3u) | (c.z >> 2u));
    }
    return c.x | (c.y << 8u) | (c.z << 16u) | 0xff000000u;
}

#endif // VOXDAG_ATTR_LOSSLESS_GLSL
