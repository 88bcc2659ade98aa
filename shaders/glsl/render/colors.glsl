// Colour of a hit voxel from the decoupled, chunked colour array (engine/attr/chunks.rs): a
// binary search of the chunk table, then the stored format's random-access decoder.
//
// The includer declares the push constant block `push` with the device addresses
//   uint64_t color_words;   // ChunkedColors::words
//   uint64_t chunk_starts;  // ChunkedColors::chunk_starts (chunk_count + 1 u64)
//   uint64_t chunk_offsets; // ChunkedColors::chunk_offsets (chunk_count + 1 u64)
// and the fields `uint color_format` (attr::ColorFormat id) and `uint chunk_count`, before
// including this file. Provides
//   uint chunk_color(uint64_t i); // RGBA8 colour i (alpha 255), i < chunk_starts[chunk_count]
#ifndef VOXDAG_RENDER_COLORS_GLSL
#define VOXDAG_RENDER_COLORS_GLSL

#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

// Format ids of attr::ColorFormat.
#define COLOR_FORMAT_RAW 0u
#define COLOR_FORMAT_LOSSLESS888 1u
#define COLOR_FORMAT_LOSSLESS565 2u
#define COLOR_FORMAT_VARBIT 3u
#define COLOR_FORMAT_PALETTE 4u

#include "attr/lossless.glsl"
#include "attr/palette.glsl"
#include "attr/varbit.glsl"

layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer ColorTableRef {
    uint64_t v[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer ColorWordsRef {
    uint w[];
};

uint chunk_color(uint64_t i) {
    // The last chunk whose start is <= i (ChunkedColors::chunk_of): starts[lo] <= i < starts[hi].
    ColorTableRef starts = ColorTableRef(push.chunk_starts);
    uint lo = 0u;
    uint hi = push.chunk_count;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    if (hi - lo > 1u) for (;;) {
        uint mid = lo + (hi - lo) / 2u;
        if (starts.v[mid] <= i) {
            lo = mid;
        } else {
            hi = mid;
        }
        if (hi - lo <= 1u) break;
    }
    uint local = uint(i - starts.v[lo]); // chunks hold far fewer than 2^32 colours
    uint64_t chunk = push.color_words + 4ul * ColorTableRef(push.chunk_offsets).v[lo];
    switch (push.color_format) {
    case COLOR_FORMAT_RAW:
        return ColorWordsRef(chunk).w[local] | 0xff000000u;
    case COLOR_FORMAT_LOSSLESS888:
    case COLOR_FORMAT_LOSSLESS565:
        return lossless_color(chunk, local);
    case COLOR_FORMAT_VARBIT:
        return varbit_color(chunk, local);
    case COLOR_FORMAT_PALETTE:
        return palette_color(chunk, local);
    }
    // Unknown format ids never reach the GPU (ColorFormat::from_id); white like the CPU's
    // undecodable colours.
    return 0xffffffffu;
}

#endif
