#version 460
// Primary rays: one invocation per pixel traces the SVDAG and shades the hit
// (render/shade.glsl, the GLSL twin of engine/render/cpu.rs), writing the sRGB colour to the
// storage image and 1 (hit) / 0 (miss) to the hit buffer. Driven by engine/render/gpu.rs.
// Buffers are reached through device addresses (push constants), so they may exceed
// maxStorageBufferRange.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

// Workgroup size: specialization constants 0 and 1 (8 x 8).
layout(local_size_x_id = 0, local_size_y_id = 1, local_size_z = 1) in;

// Specialization constants 2 and 3: whether the hit's colour index and the shadow ray are
// compiled in (`PrimaryVariant` in engine/render/gpu.rs: the colour index where the scene has
// colours or first hits are written, shadows where `RENDER_FLAG_SHADOWS` is set).
layout(constant_id = 2) const bool PRIMARY_COLOR_INDEX = true;
layout(constant_id = 3) const bool PRIMARY_SHADOWS = true;

layout(set = 0, binding = 0, rgba8) uniform writeonly image2D out_image;

#include "shared/render_params.h"
#include "gen/render.glsl"

struct FirstHit {
    FIRST_HIT_MEMBERS
};

layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer ParamsRef {
    RenderParams params;
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer WordsRef {
    uint w[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer Words64Ref {
    uint64_t w[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer HitsRef {
    uint h[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) writeonly buffer FirstHitsRef {
    FirstHit h[];
};

// Members: `PrimaryPush` in engine/render/gpu_shared.rs.
layout(push_constant, std430) uniform Push { PRIMARY_PUSH_MEMBERS } push;

#include "render/colors.glsl"

uint dag_word(uint i) {
    return WordsRef(push.words).w[i];
}

// Words i and i + 1 as one 64-bit load (4-byte aligned: x86 lavapipe and GPUs load it as two
// words' worth; one per-lane loop on lavapipe instead of two).
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer WordPairRef {
    uint64_t v;
};

#define DAG_HAS_WORD_PAIR 1
uvec2 dag_word_pair(uint i) {
    return unpackUint2x32(WordPairRef(push.words + 4ul * uint64_t(i)).v);
}

#define DAG_TABLES_BINDING 1
#include "render/dag_tables.glsl"

uint64_t dag_node_voxels(uint i) {
    return Words64Ref(push.node_voxels).w[i];
}

uint dag_color(uint64_t i) {
    return chunk_color(i);
}

#include "render/traverse.glsl"
#include "render/shade.glsl"

void main() {
    RenderParams p = ParamsRef(push.params).params;
    uvec2 pixel = gl_GlobalInvocationID.xy;
    if (pixel.x >= p.width || pixel.y >= p.height) {
        return;
    }
    traverse_begin(p.root_level);
    bool hit;
    Hit h;
    vec4 color = shade_pixel_hit(pixel, p, PRIMARY_COLOR_INDEX, PRIMARY_SHADOWS, hit, h);
    imageStore(out_image, ivec2(pixel), color);
    uint i = pixel.y * p.width + pixel.x;
    if (push.hits != 0ul) {
        HitsRef(push.hits).h[i] = hit ? 1u : 0u;
    }
    // Renders that write first hits run with the colour index (the host's variant): the variant
    // without it compiles the (masked) write out.
    if (PRIMARY_COLOR_INDEX && push.first_hits != 0ul) {
        FirstHit f;
        f.hit = hit ? 1u : 0u;
        f.t_bits = hit ? floatBitsToUint(h.t) : 0u;
        for (uint k = 0u; k < 3u; k++) {
            f.voxel[k] = hit ? h.voxel[k] : 0u;
            f.normal[k] = hit ? h.normal[k] : 0;
        }
        f.color_index = hit ? h.color_index : 0ul;
        FirstHitsRef(push.first_hits).h[i] = f;
    }
}
