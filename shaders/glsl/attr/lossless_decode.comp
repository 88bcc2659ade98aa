#version 460
// Lossless colour decoder: invocation i (grid-stride over `count`) writes colour i of the chunk,
// decoded by `lossless_color` (attr/lossless.glsl), to `out[i]`. Used by `LosslessGpu::decode_all`
// (engine/attr_gpu/lossless.rs) and by the tests that compare the GLSL decoder with the CPU one.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x_id = 0) in;

#include "attr/lossless.glsl"

layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer DecodedColors {
    uint c[];
};

// Mirror of `DecodePush` in engine/attr_gpu/lossless.rs (24 bytes).
#include "gen/attr.glsl"
// Members: `DecodePush` in engine/attr_gpu/gpu_shared.rs.
layout(push_constant, std430) uniform Push { DECODE_PUSH_MEMBERS } push;

void main() {
    DecodedColors out_colors = DecodedColors(push.out_colors);
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) for (;;) {
        out_colors.c[i] = lossless_color(push.chunk, i);
        i += stride;
        if (i >= push.count) break;
    }
}
