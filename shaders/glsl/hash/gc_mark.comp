#version 460
// Garbage collection, mark: every live handle sets its slot's bit in its slab's active word
// (atomicOr). Sentinels (HASH_MISS, HASH_INVALID) are skipped; handles beyond the pool or in a
// free slab (stale) are counted in `bad_handles` and ignored: a bit in a free slab would break
// the allocator's all-zero invariant. Loop bounds are uniform in the workgroup (no early exit);
// one handle per invocation in both team modes, only the bad-handle count differs.
#include "hash/gc_common.glsl"

void main() {
    HashWords handles = HashWords(push.handles);
    uint pool_slabs = push.blocks * HASH_SLABS_PER_BLOCK;
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint base = gl_WorkGroupID.x * gl_WorkGroupSize.x;
    if (base < push.count) for (;;) {
        uint i = base + gl_LocalInvocationID.x;
        uint handle = i < push.count ? handles.w[i] : HASH_MISS;
        bool sentinel = handle == HASH_MISS || handle == HASH_INVALID;
        uint slab_index = handle >> 5u;
        bool valid = !sentinel && slab_index < pool_slabs;
        if (valid) {
            uint local = slab_index % HASH_SLABS_PER_SUPER_BLOCK;
            HashWords bitmasks = HashWords(hash_super_block(push.super_blocks,
                                                            slab_index / HASH_SLABS_PER_SUPER_BLOCK));
            valid = ((bitmasks.w[local / 32u] >> (local % 32u)) & 1u) != 0u;
        }
        if (valid) {
            HashWords slab = HashWords(hash_slab_address(push.super_blocks, slab_index));
            atomicOr(slab.w[HASH_SLAB_ACTIVE], 1u << (handle & 31u));
        }
        bool bad = !sentinel && !valid;
        if (TEAM == 1u) {
            // Single lanes: no subgroup operation (bad handles are rare, one atomic each).
            if (bad) atomicAdd(GcCountersRef(push.items).bad_handles, 1u);
        } else {
            uint bad_count = subgroupAdd(bad ? 1u : 0u);
            if (bad_count != 0u && subgroupElect()) {
                atomicAdd(GcCountersRef(push.items).bad_handles, bad_count);
            }
        }
        base += stride;
        if (base >= push.count) break;
    }
}
