#version 460
// Test pass of shaders/glsl/attr/varbit.glsl: out[i] = varbit_color(chunk, i) for i < count.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

#include "attr/varbit.glsl"

layout(local_size_x = 64) in;

layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer OutWords {
    uint w[];
};

#include "gen/test.glsl"
layout(push_constant, std430) uniform Push { DECODE_TEST_PUSH_MEMBERS } push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) {
        OutWords(push.out_addr).w[i] = varbit_color(push.chunk_addr, i);
    }
}
