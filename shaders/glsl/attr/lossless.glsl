// Random-access decoder of the lossless colour codec: the GLSL twin of
// `attr::lossless::decode` (engine/attr/lossless.rs; layout in docs/colors-lossless.md).
//
//   uint lossless_color(uint64_t chunk_words_address, uint index)
//
// returns colour `index` of the encoded chunk at `chunk_words_address` as an opaque RGBA8 word
// (r | g << 8 | b << 16 | 0xff << 24). No validation: the host validated the chunk
// (`attr::lossless::validate`) before uploading it, and `index` is below the chunk's colour
// count. The includer enables GL_EXT_buffer_reference and
// GL_EXT_shader_explicit_arithmetic_types_int64. No bindings, no `main`.
#ifndef VOXDAG_ATTR_LOSSLESS_GLSL
#define VOXDAG_ATTR_LOSSLESS_GLSL

layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer LosslessWords {
    uint w[];
};

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

// Mask words of a block from header word B: 0 with one run, else `((b >> 27) & 3) + 1`.
uint lossless_mask_words(uint head_b) {
    return ((head_b >> 12u) & 127u) == 0u ? 0u : ((head_b >> 27u) & 3u) + 1u;
}

uint lossless_color(uint64_t chunk_words_address, uint index) {
    LosslessWords chunk = LosslessWords(chunk_words_address);
    uint block = index >> 7u;
    uint i = index & 127u;
    // Block 0 starts the chunk; the offset table of blocks 1.. follows it, so its position is
    // block 0's size (block 0 holds 128 colours whenever there are more blocks).
    uint64_t block_offset = 0ul;
    if (block > 0u) {
        uint h0 = chunk.w[1];
        uint runs0 = ((h0 >> 12u) & 127u) + 1u;
        uint palette0 = ((h0 >> 19u) & 127u) + 1u;
        uint index_bits0 = ((h0 >> 26u) & 1u) != 0u ? uint(findMSB(palette0 - 1u) + 1) : 0u;
        uint width0 = (h0 & 15u) + ((h0 >> 4u) & 15u) + ((h0 >> 8u) & 15u);
        uint stream_bits0 = palette0 * 9u + runs0 * index_bits0 + 128u * width0;
        uint at = 2u + lossless_mask_words(h0) + (stream_bits0 + 31u) / 32u + 2u * (block - 1u);
        block_offset = uint64_t(chunk.w[at]) | (uint64_t(chunk.w[at + 1u]) << 32);
    }
    uint64_t block_address = chunk_words_address + block_offset * 4ul;
    LosslessWords blk = LosslessWords(block_address);

    uint head_a = blk.w[0];
    uint head_b = blk.w[1];
    uvec3 minimum = uvec3(head_a & 0xffu, (head_a >> 8u) & 0xffu, (head_a >> 16u) & 0xffu);
    uvec3 shift = uvec3(head_b & 15u, (head_b >> 4u) & 15u, (head_b >> 8u) & 15u);
    uint runs = ((head_b >> 12u) & 127u) + 1u;
    uint palette = ((head_b >> 19u) & 127u) + 1u;
    bool indexed = ((head_b >> 26u) & 1u) != 0u;
    bool rgb565 = ((head_b >> 29u) & 1u) != 0u;

    // Run of colour i: set mask bits at positions 0..=i (bit 0 is always clear).
    uint run = 0u;
    uint mask_words = lossless_mask_words(head_b);
    if (mask_words > 0u) {
        uint mw = i >> 5u;
        for (uint k = 0u; k < mw; k++) {
            run += bitCount(blk.w[2u + k]);
        }
        uint bit = i & 31u;
        uint keep = bit == 31u ? 0xffffffffu : ((2u << bit) - 1u);
        run += bitCount(blk.w[2u + mw] & keep);
    }
    LosslessWords stream = LosslessWords(block_address + uint64_t(2u + mask_words) * 4ul);

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
    if (rgb565) {
        // Bit replication to 8 bits (`attr::lossless::expand`).
        c = uvec3((c.x << 3u) | (c.x >> 2u), (c.y << 2u) | (c.y >> 4u), (c.z << 3u) | (c.z >> 2u));
    }
    return c.x | (c.y << 8u) | (c.z << 16u) | 0xff000000u;
}

#endif // VOXDAG_ATTR_LOSSLESS_GLSL
