#version 460
// Test shader of the GPU primitives (tests/gpu_primitives.rs): a pass sized on the GPU by
// vkCmdDispatchIndirect over a compaction's survivors. `count_args` holds [count, x, y, z];
// invocation i (linear over the 2D grid) counts itself in stats[0] and, when i < count,
// writes out[i] = in[i] * 3 + 1 and counts itself in stats[1].
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x_id = 0) in;

layout(buffer_reference, std430, buffer_reference_align = 4) buffer Words {
    uint w[];
};

#include "gen/test.glsl"
layout(push_constant, std430) uniform Push { INDIRECT_CONSUME_PUSH_MEMBERS } push;

void main() {
    uint group = gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
    uint i = group * gl_WorkGroupSize.x + gl_LocalInvocationID.x;
    Words stats = Words(push.stats);
    atomicAdd(stats.w[0], 1u);
    if (i < Words(push.count_args).w[0]) {
        Words(push.output_words).w[i] = Words(push.input_words).w[i] * 3u + 1u;
        atomicAdd(stats.w[1], 1u);
    }
}
