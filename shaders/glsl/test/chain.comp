#version 460
// Test shader of the GPU layer: one link of a chain of dependent passes. Invocation i
// (grid-stride over `count`) reads its neighbour from the previous pass's output:
//   dst[i] = src[(i + 1) % count] * 31 + pass + i   (wrapping u32)
// so every pass depends on the one before it; the host ping-pongs src and dst.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x_id = 0) in;

layout(buffer_reference, std430, buffer_reference_align = 4) buffer Words {
    uint w[];
};

#include "gen/test.glsl"
layout(push_constant, std430) uniform Push { CHAIN_PUSH_MEMBERS } push;

void main() {
    Words src = Words(push.src_addr);
    Words dst = Words(push.dst_addr);
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < push.count; i += stride) {
        uint next = i + 1u == push.count ? 0u : i + 1u;
        dst.w[i] = src.w[next] * 31u + push.pass_index + i;
    }
}
