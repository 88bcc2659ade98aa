#version 460
// Duplicate-detection table, pass 3 of 3 (see dedup_common.glsl): every input reads the minimum
// value of its key's entry: its representative.
#include "hash/dedup_common.glsl"

void resolve(uint i) {
    uint canon = Words(push.canon).w[i];
    if (canon == ~0u) {
        Words(push.reps).w[i] = ~0u;
        return;
    }
    if (TEAM == 1u) {
        // Probe table: canon is the slot.
        Words(push.reps).w[i] = ~Words(push.table).w[push.buckets + canon];
        return;
    }
    Words slab = slab_at(canon / SLOTS);
    Words(push.reps).w[i] = ~slab.w[VALUES_OFFSET + canon % SLOTS];
}

void main() {
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) for (;;) {
        resolve(i);
        i += stride;
        if (i >= push.count) break;
    }
}
