#version 460
// Slab hash insert pass: places every item whose handle is still HASH_MISS and writes its new
// handle. Items are assumed absent (no search here; duplicates inside a batch get separate
// slots), except with HASH_FLAG_CLAIMS: then only the representatives the claim table names
// are placed, the other copies get HASH_INVALID and their representative in reps (see
// hash/claims.glsl). One item per team (a subgroup, or one lane) at a time: walk the bucket's
// chain from its hint, claim a free slot in the first slab that has one, else allocate a slab
// and link it at the end with a CAS. When no slab can be allocated the handle stays HASH_MISS
// and status.exhausted counts it: the host grows the pool and runs the pass again (only
// HASH_MISS items are retried). A mixed batch (engine/hash/mixed.rs, claim rounds only) runs
// this for items of every size. Driven by engine/hash/table.rs and engine/hash/mixed.rs.
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
#include "hash/insert_pass.glsl"

void main() {
    hash_insert_pass(hash_count());
}
