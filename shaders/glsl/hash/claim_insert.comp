#version 460
// The search-and-claim pass and the claimed insert round of a mixed batch (engine/hash/mixed.rs)
// in one dispatch of ONE workgroup, a workgroup barrier between them instead of a second
// dispatch: the host uses it when the batch fits one workgroup's grid stride. On lavapipe every
// dispatch costs a hand-off to the driver's worker threads (~13 us of its queue thread plus the
// workers' wake-ups), more than the work of the small levels at the top of an edit
// (docs/editing-gpu.md, "Speed, round 13"). Single lanes only, like both passes.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_EXT_shader_atomic_int64 : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require

#include "shared/hash_layout.h"
#include "hash/common.glsl"
#include "hash/alloc.glsl"
#include "hash/slab.glsl"
#include "hash/claims.glsl"
#include "hash/claim_pass.glsl"
#include "hash/insert_pass.glsl"

void main() {
    // Both passes take the batch's items as counted here (the claim changes no count). Every
    // item of a mixed batch takes its size's entry (hash_select), so the insert needs no fresh
    // copy of the push constants (as in edit/merge_small_levels.comp).
    uint batch_count = hash_count();
    hash_claim_pass(batch_count);
    // Every claim (handles, representatives, claim-table copies) before any insert reads them.
    memoryBarrierBuffer();
    barrier();
    hash_insert_pass(batch_count);
}
