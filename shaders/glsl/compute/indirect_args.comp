#version 460
// Turns a count computed on the GPU into vkCmdDispatchIndirect arguments. The buffer holds
// [count, x, y, z]: groups = ceil(count / group_size) workgroups as a 2D grid
// x = min(groups, 65535), y = ceil(groups / 65535), z = 1 (x = 0 when count is 0), so consumers
// take their linear workgroup index as gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x
// and compare invocations with the count. One invocation. Driven by engine/compute/scan.rs.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 1) in;

layout(buffer_reference, std430, buffer_reference_align = 4) buffer CountArgs {
    uint v[4];
};

// Mirror of `ArgsPush` in engine/compute/scan.rs (16 bytes).
#include "gen/compute.glsl"
// Members: `ArgsPush` in engine/compute/gpu_shared.rs.
layout(push_constant, std430) uniform Push { ARGS_PUSH_MEMBERS } push;

void main() {
    CountArgs b = CountArgs(push.count_args);
    uint count = b.v[0];
    uint64_t groups = (uint64_t(count) + uint64_t(push.group_size) - 1ul) / uint64_t(push.group_size);
    b.v[1] = uint(min(groups, 65535ul));
    b.v[2] = uint(max((groups + 65534ul) / 65535ul, 1ul));
    b.v[3] = 1u;
}
