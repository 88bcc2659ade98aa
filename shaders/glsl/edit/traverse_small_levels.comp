#version 460
// The traversal's small levels in ONE dispatch of ONE SIMD group (engine/edit/gpu.rs
// `GpuHashDag::traverse`): the first level of a submission (its count known to the host) and
// then each next inner level of the submission while its entries, counted on the GPU by the
// level above, are at most chain.max_entries; a subgroup barrier between levels. A level
// done here gets zero workgroups in its own indirect dispatch's arguments (recorded after this
// one), which lavapipe then runs without handing it to its worker threads; the levels after
// the first too large keep their dispatches. Each level's parameters are the push constants
// its own dispatch has (edit/traverse_level.glsl reads `push`). On lavapipe every dispatch with
// workgroups costs a hand-off to the driver's worker threads (~13 us of its queue thread and
// the workers' wake-ups), more than the few entries of an edit's top levels; the workgroup is
// one SIMD group because lavapipe runs every SIMD group of a workgroup as a coroutine that each
// barrier suspends (docs/editing-gpu.md, "Speed, rounds 15 and 16").
#extension GL_KHR_shader_subgroup_basic : require
#define EDIT_PARAMS_IN_MEMORY
#include "edit/common.glsl"
#include "edit/traverse_level.glsl"

// One SIMD group (the subgroup size; the edit passes' constants are 0 and 1).
layout(local_size_x_id = 2) in;

layout(push_constant, std430) uniform Push { TRAVERSE_CHAIN_PUSH_MEMBERS } chain;

void main() {
    uint lane = gl_LocalInvocationID.x;
    uint lanes = gl_WorkGroupSize.x;
    // The exit tests at the loop's end (docs/gpu.md, "Loops on lavapipe"); the counts they read
    // were written before the barrier and are the same in every lane.
    uint k = 0u;
    for (;;) {
        push = edit_record(k * EDIT_PUSH_UVEC4S);
        edit_traverse_level(lane, lanes, edit_count());
        // (One subgroup: a subgroup barrier orders the levels, as in merge_small_levels.)
        subgroupMemoryBarrierBuffer();
        subgroupBarrier();
        if (k > 0u && lane == 0u) {
            // Done here: the level's own dispatch finds zero workgroups.
            Words(push.count_at).w[1] = 0u;
        }
        k += 1u;
        if (k >= chain.levels) break;
        push = edit_record(k * EDIT_PUSH_UVEC4S);
        if (edit_count() > chain.max_entries) break;
    }
}
