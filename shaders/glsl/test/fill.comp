#version 460
// Test shader of the GPU layer: exercises buffer device addresses, specialization constants,
// push constants and the subgroup size. Invocation i (grid-stride over `count`) writes
//   out[i] = i * MULTIPLIER + push.seed
// and, when `aux` is non-zero, aux[i] = gl_SubgroupSize, for the host to compare exactly.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_KHR_shader_subgroup_basic : require

layout(local_size_x_id = 0) in;
layout(constant_id = 1) const uint MULTIPLIER = 1;

layout(buffer_reference, std430, buffer_reference_align = 4) buffer Words {
    uint w[];
};

#include "gen/test.glsl"
layout(push_constant, std430) uniform Push { FILL_PUSH_MEMBERS } push;

void main() {
    Words out_words = Words(push.out_addr);
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < push.count; i += stride) {
        out_words.w[i] = i * MULTIPLIER + push.seed;
        if (push.aux_addr != 0ul) {
            Words aux = Words(push.aux_addr);
            aux.w[i] = gl_SubgroupSize;
        }
    }
}
