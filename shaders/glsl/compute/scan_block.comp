#version 460
// Exclusive scan, downsweep: workgroup w scans its block (each invocation ITEMS consecutive
// elements, then the workgroup sum) and adds offsets[w], the exclusive scan of the block sums
// (none when `offsets` is 0: a single block). The last workgroup writes the grand total to
// `total` (when non-zero). Mode 0 writes the scan to `output_words` (in place is allowed);
// mode 1 is stream compaction: `input_words` are flags, and each element with a non-zero flag
// copies values[i] to output_words[its exclusive count]. Driven by engine/compute/scan.rs.
#include "compute/common.glsl"

// Mirror of `BlockPush` in engine/compute/scan.rs (48 bytes).
#include "gen/compute.glsl"
// Members: `BlockPush` in engine/compute/gpu_shared.rs.
layout(push_constant, std430) uniform Push { BLOCK_PUSH_MEMBERS } push;

void main() {
    uint w = workgroup_linear();
    uint groups = max((push.n + BLOCK - 1u) / BLOCK, 1u);
    if (w >= groups) {
        return;
    }
    bool compact = push.mode == 1u;
    U32s src = U32s(push.input_words);
    uint base = w * BLOCK + gl_LocalInvocationID.x * ITEMS;
    uint sum = 0u;
    for (uint j = 0u; j < ITEMS; j++) {
        uint i = base + j;
        if (i < push.n) {
            uint x = src.v[i];
            sum += compact ? uint(x != 0u) : x;
        }
    }
    uint block_total;
    uint running = wg_exclusive_add(sum, block_total);
    uint offset = push.offsets != 0ul ? U32s(push.offsets).v[w] : 0u;
    running += offset;
    U32s dst = U32s(push.output_words);
    // Re-read rather than keep ITEMS registers: the block is still in cache, and in place
    // (input == output) every invocation reads its own elements before it writes them.
    for (uint j = 0u; j < ITEMS; j++) {
        uint i = base + j;
        if (i < push.n) {
            uint x = src.v[i];
            if (compact) {
                if (x != 0u) {
                    dst.v[running] = U32s(push.values).v[i];
                    running += 1u;
                }
            } else {
                dst.v[i] = running;
                running += x;
            }
        }
    }
    if (push.total != 0ul && w == groups - 1u && gl_LocalInvocationID.x == 0u) {
        U32s(push.total).v[0] = offset + block_total;
    }
}
