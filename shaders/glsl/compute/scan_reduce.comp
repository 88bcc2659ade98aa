#version 460
// Exclusive scan, upsweep: workgroup w writes the sum of its block of input elements to
// partials[w] (with `predicate` set, each element counts as 1 when non-zero, else 0: the
// compaction count). Driven by engine/compute/scan.rs.
#include "compute/common.glsl"

// Mirror of `ReducePush` in engine/compute/scan.rs (24 bytes).
#include "gen/compute.glsl"
// Members: `ReducePush` in engine/compute/gpu_shared.rs.
layout(push_constant, std430) uniform Push { REDUCE_PUSH_MEMBERS } push;

void main() {
    uint w = workgroup_linear();
    // Whole workgroups past the last block leave together (uniform per workgroup).
    if (w >= (push.n + BLOCK - 1u) / BLOCK) {
        return;
    }
    U32s src = U32s(push.input_words);
    uint base = w * BLOCK + gl_LocalInvocationID.x * ITEMS;
    uint sum = 0u;
    for (uint j = 0u; j < ITEMS; j++) {
        uint i = base + j;
        if (i < push.n) {
            uint x = src.v[i];
            sum += push.predicate != 0u ? uint(x != 0u) : x;
        }
    }
    uint total;
    wg_exclusive_add(sum, total);
    if (gl_LocalInvocationID.x == 0u) {
        U32s(push.partials).v[w] = total;
    }
}
