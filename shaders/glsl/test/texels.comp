#version 460
// Test shader of the GPU layer: uniform texel buffers (`TexelBuffer`, `BindingKind::TexelBuffer`).
// Invocation i (grid-stride over `count`) fetches texel j = (i * 7919) % count, so that the
// lanes of a SIMD group read scattered texels, and writes
//   out[2 j] = texel.x + push.seed, out[2 j + 1] = texel.y + push.seed.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 64) in;

layout(buffer_reference, std430, buffer_reference_align = 4) buffer Words {
    uint w[];
};

layout(set = 0, binding = 0) uniform usamplerBuffer texels;

#include "gen/test.glsl"
layout(push_constant, std430) uniform Push { FILL_PUSH_MEMBERS } push;

void main() {
    Words out_words = Words(push.out_addr);
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < push.count; i += stride) {
        uint j = uint((uint64_t(i) * 7919ul) % uint64_t(push.count));
        uvec2 t = texelFetch(texels, int(j)).xy;
        out_words.w[2u * j] = t.x + push.seed;
        out_words.w[2u * j + 1u] = t.y + push.seed;
    }
}
