// Random-access decoder of the Dado et al. palette colour format, the GLSL twin of
// `attr::dado::decode` (engine/attr/dado.rs documents the words).
//
// The includer enables GL_EXT_buffer_reference and GL_EXT_shader_explicit_arithmetic_types_int64
// before including this file. Provides
//   uint palette_color(uint64_t chunk_words_address, uint index); // RGBA8, alpha 255
// The chunk must have passed `attr::dado::decode_all` (no bounds checks here).
#ifndef VOXDAG_ATTR_PALETTE_GLSL
#define VOXDAG_ATTR_PALETTE_GLSL

#define PALETTE_BLOCK_COLORS 1024u

layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer PaletteWords {
    uint w[];
};

// `bits` (1..24) bits at bit position `bit` of the chunk.
uint palette_read_bits(PaletteWords words, uint bit, uint bits) {
    uint word = bit >> 5;
    uint shift = bit & 31u;
    uint v = words.w[word] >> shift;
    if (shift + bits > 32u) {
        v |= words.w[word + 1u] << (32u - shift);
    }
    return v & ((1u << bits) - 1u);
}

uint palette_color(uint64_t chunk_words_address, uint index) {
    PaletteWords words = PaletteWords(chunk_words_address);
    uint offset = words.w[index / PALETTE_BLOCK_COLORS];
    uint size = words.w[offset];
    uint stream = (offset + 1u) * 32u;
    uint entry = 0u;
    if (size > 1u) {
        uint bits = uint(findMSB(size - 1u)) + 1u; // ceil(log2(size))
        entry = palette_read_bits(words, stream + 24u * size + bits * (index % PALETTE_BLOCK_COLORS), bits);
    }
    return palette_read_bits(words, stream + 24u * entry, 24u) | 0xff000000u;
}

#endif // VOXDAG_ATTR_PALETTE_GLSL
