// Wavefront path tracer (Laine, Karras & Aila 2013, "Megakernels considered harmful"): the
// state the passes pt_generate -> (pt_extend -> pt_shade -> pt_shadow)* -> pt_accumulate pass
// through memory, and the queue accessors. Paths are stored per pixel; the queues hold pixel
// indices. The extension queue is rebuilt after each shade pass by stream compaction of the
// shade pass's survival flags (engine/compute, stable: pixel order); the shadow queue is an
// atomic append. Each queue's count word is followed by vkCmdDispatchIndirect arguments
// ([count, x, y, z], engine/compute `record_indirect_args`), so every pass is sized on the GPU.
#ifndef VOXDAG_RENDER_PT_WAVE_GLSL
#define VOXDAG_RENDER_PT_WAVE_GLSL

#include "render/pt_common.glsl"

// One path: the ray to trace next, its throughput and radiance so far, and the last hit.
struct PtPath {
    vec4 origin;      // xyz
    vec4 dir;         // xyz
    vec4 throughput;  // xyz
    vec4 radiance;    // xyz
    uint64_t color_index;
    float t;
    uint normal_code; // pt_normal_code, 0: the last ray escaped
};

// A shadow ray towards the sun and what it adds to its pixel when unoccluded.
struct PtShadowRay {
    vec4 origin;       // xyz; w: the pixel (uint bits)
    vec4 contribution; // xyz
};

layout(buffer_reference, std430, buffer_reference_align = 16) buffer PtPathsRef {
    PtPath p[];
};
layout(buffer_reference, std430, buffer_reference_align = 16) buffer PtShadowsRef {
    PtShadowRay r[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) buffer PtQueueRef {
    uint v[];
};

// Invocations per workgroup of every wavefront pass (PT_WAVE_GROUP in pathtrace_gpu.rs).
#define PT_WAVE_GROUP 64u

// Linear invocation index under the 2D indirect grid of `record_indirect_args`.
uint pt_wave_slot() {
    uint group = gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
    return group * PT_WAVE_GROUP + gl_LocalInvocationID.x;
}

// Extension queue read by the passes of bounce k (ping-pong between the two queues).
uint64_t pt_queue_in(PtParams pt) {
    return (push.bounce & 1u) == 0u ? pt.queue_a : pt.queue_b;
}

#endif
