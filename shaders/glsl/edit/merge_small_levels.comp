#version 460
// The merge of an edit's small top levels in ONE dispatch of ONE workgroup (engine/edit/gpu/
// small_levels.rs): per level bottom-up, build_items, the mixed batch's search and claim, and
// its claimed insert round, a subgroup barrier after each; then the root level's resolve.
// Each pass's body is the one its own dispatch runs (edit/build_items_pass.glsl,
// hash/claim_pass.glsl, hash/insert_pass.glsl, edit/resolve_pass.glsl), reading its
// parameters from the chain's records instead of push constants. On lavapipe every dispatch
// costs a hand-off to the driver's worker threads (~13 us of its queue thread and the workers'
// wake-ups), more than the work of the few dozen nodes of an edit's top levels, which took two
// dispatches each (docs/editing-gpu.md, "Speed, round 15"). Single lanes only, like the claim
// passes; build_items reads through addresses (the levels' word views differ).
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require

// The edit passes' parameters are `push` in their sources, as are the hash passes': here both
// are variables set per level, the edit side's renamed while its sources are read. The edit
// specialization constants follow the hash passes' five (engine/edit/gpu/small_levels.rs).
#define EDIT_PARAMS_IN_MEMORY
#define EDIT_SPEC_ID_BASE 5
#define push edit_level
#include "edit/common.glsl"

// build_items' reads, through addresses.
uint input_word(uint i) {
    return Words(push.src).w[i];
}

uvec2 input_pair(uint k) {
    return uvec2(input_word(2u * k), input_word(2u * k + 1u));
}

uint below_result(uint j) {
    return Words(push.src2).w[j];
}

uint below_resolve(EditLevelHandles level, Words slots, uint j, uint r) {
    return edit_resolve_slot(level, slots.w[j], r);
}

#include "edit/build_items_pass.glsl"
#include "edit/resolve_pass.glsl"
#undef push

#define HASH_PARAMS_IN_MEMORY
#include "shared/hash_layout.h"
#include "hash/common.glsl"
#include "hash/alloc.glsl"
#include "hash/slab.glsl"
#include "hash/claims.glsl"
#include "hash/claim_pass.glsl"
#include "hash/insert_pass.glsl"

layout(push_constant, std430) uniform Push { SMALL_LEVELS_PUSH_MEMBERS } chain;

// The records (engine/edit/gpu/small_levels.rs), in uvec4 texels: the levels' EditParams, then
// their batches' HashParams, then per level its batch's HASH_MIXED_SIZES entries.
uint g_level;

HashParams hash_record(uint at) {
    uvec4 t[HASH_PUSH_UVEC4S];
    [[unroll]] for (uint k = 0u; k < HASH_PUSH_UVEC4S; ++k) {
        t[k] = texelFetch(edit_records, int(at + k));
    }
    return HashParams(HASH_PUSH_FROM_UVEC4S(t));
}

HashParams hash_level_entry(uint s) {
    uint entries_at = chain.levels * (EDIT_PUSH_UVEC4S + HASH_PUSH_UVEC4S);
    return hash_record(entries_at + (g_level * HASH_MIXED_SIZES + s) * HASH_PUSH_UVEC4S);
}

// Every write of a pass (items, counters, handles, representatives, results) before the next
// pass of the workgroup reads them. The workgroup is one subgroup, so a subgroup barrier
// orders them: lavapipe compiles a workgroup barrier into a coroutine suspension (every value
// live across it saved and restored, a return to the driver and a resumption), a subgroup one
// into a fence (docs/gpu.md, "Subgroup barriers in one-subgroup workgroups").
void pass_done() {
    subgroupMemoryBarrierBuffer();
    subgroupBarrier();
}

void main() {
    uint lane = gl_LocalInvocationID.x;
    uint lanes = gl_WorkGroupSize.x;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe"); the host records at
    // least one level.
    uint l = 0u;
    for (;;) {
        g_level = l;
        edit_level = edit_record(l * EDIT_PUSH_UVEC4S);
        edit_build_items_pass(lane, lanes);
        pass_done();
        // The batch's entries and counts read once for both passes (the claim changes no
        // count). Every item of a mixed batch takes its size's entry (hash_select), so the
        // insert needs no fresh copy of the batch's parameters.
        push = hash_record(chain.levels * EDIT_PUSH_UVEC4S + l * HASH_PUSH_UVEC4S);
        uint batch_count = hash_count();
        hash_claim_pass(batch_count);
        pass_done();
        hash_insert_pass(batch_count);
        pass_done();
        l += 1u;
        if (l >= chain.levels) break;
    }
    // The root level's pending result (edit_level is still the last level's).
    edit_resolve_pass(lane, lanes);
}
