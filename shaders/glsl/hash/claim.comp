#version 460
// Search-and-claim pass (single lanes; engine/hash/claim.rs): handles[i] = handle of items[i]
// in the table, or HASH_MISS; every missing item also gets a copy in the claim table
// (hash/claims.glsl), so that the insert round that follows (HASH_FLAG_CLAIMS) inserts one
// representative per distinct item. reps[i] = i (the insert round overwrites the missing
// items' entries with their representative). The batch's duplicate detection thus costs no
// pass of its own. A mixed batch (engine/hash/mixed.rs) runs this for items of every size.
// Driven by engine/hash/table.rs and engine/hash/mixed.rs.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require

#include "shared/hash_layout.h"
#include "hash/common.glsl"
#include "hash/slab.glsl"
#include "hash/claims.glsl"
#include "hash/claim_pass.glsl"

void main() {
    hash_claim_pass(hash_count());
}
