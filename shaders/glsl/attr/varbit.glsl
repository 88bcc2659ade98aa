// Random-access decoder of the Dolonius et al. variable-bitrate colour format, the GLSL twin of
// `attr::varbit::decode` (engine/attr/varbit.rs documents the words). Integer arithmetic only,
// so the result is bit-identical to the CPU decoder.
//
// The includer enables GL_EXT_buffer_reference and GL_EXT_shader_explicit_arithmetic_types_int64
// before including this file. Provides
//   uint varbit_color(uint64_t chunk_words_address, uint index); // RGBA8, alpha 255
// The chunk must have passed `attr::varbit::validate` (no bounds checks here).
#ifndef VOXDAG_ATTR_VARBIT_GLSL
#define VOXDAG_ATTR_VARBIT_GLSL

#define VARBIT_MACRO_BLOCK_COLORS 16384u

layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer VarbitWords {
    uint w[];
};

uvec3 varbit_expand565(uint c) {
    uint r = c & 31u;
    uint g = (c >> 5) & 63u;
    uint b = (c >> 11) & 31u;
    return uvec3((r << 3) | (r >> 2), (g << 2) | (g >> 4), (b << 3) | (b >> 2));
}

uint varbit_rgba(uvec3 c) {
    return c.r | (c.g << 8) | (c.b << 16) | 0xff000000u;
}

uint varbit_color(uint64_t chunk_words_address, uint index) {
    VarbitWords words = VarbitWords(chunk_words_address);
    uint block_count = words.w[0];
    uint macro_count = words.w[1];
    uint header = 2u + 2u * macro_count;
    uint m = index / VARBIT_MACRO_BLOCK_COLORS;
    uint local = index % VARBIT_MACRO_BLOCK_COLORS;
    uint lo = words.w[2u + 2u * m];
    uint hi = m + 1u < macro_count ? words.w[4u + 2u * m] : block_count;
    // The last block whose first colour is <= local.
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    if (hi - lo > 1u) for (;;) {
        uint mid = (lo + hi) / 2u;
        if ((words.w[header + 2u * mid] & (VARBIT_MACRO_BLOCK_COLORS - 1u)) <= local) {
            lo = mid;
        } else {
            hi = mid;
        }
        if (hi - lo <= 1u) break;
    }
    uint head = words.w[header + 2u * lo];
    uint color = words.w[header + 2u * lo + 1u];
    uint offset = head >> 16;
    if (offset == 0xffffu) {
        uvec3 c = uvec3(color & 1023u, (color >> 10) & 4095u, color >> 22);
        uvec3 maxv = uvec3(1023u, 4095u, 1023u);
        return varbit_rgba((c * 255u + maxv / 2u) / maxv);
    }
    uint bits = ((head >> 14) & 3u) + 1u;
    uint weights = header + 2u * block_count + words.w[3u + 2u * m];
    uint bit = weights * 32u + offset + (local - (head & (VARBIT_MACRO_BLOCK_COLORS - 1u))) * bits;
    uint word = bit >> 5;
    uint shift = bit & 31u;
    uint w = words.w[word] >> shift;
    if (shift + bits > 32u) {
        w |= words.w[word + 1u] << (32u - shift);
    }
    w &= (1u << bits) - 1u;
    uint n = (1u << bits) - 1u;
    uvec3 a = varbit_expand565(color & 0xffffu);
    uvec3 b = varbit_expand565(color >> 16);
    return varbit_rgba((a * (n - w) + b * w + n / 2u) / n);
}

#endif // VOXDAG_ATTR_VARBIT_GLSL
