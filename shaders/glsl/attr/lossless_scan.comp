#version 460
// Lossless colour encoder, pass 2 of 3: one workgroup computes every block's word offset in the
// chunk, an exclusive prefix sum of the block sizes (`plans[4 * b + 2]`) starting after the chunk
// header and the offset table, into `offsets[b]`; `offsets[blocks]` receives the chunk's total
// words. Each invocation sums a contiguous range of blocks, the range sums are scanned in shared
// memory (Hillis-Steele), then each invocation writes its range. No subgroup operations, so any
// subgroup size works. Driven by engine/attr_gpu/lossless.rs.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x_id = 0) in;

#include "attr/lossless_encode.glsl"

// Mirror of `ScanPush` in engine/attr_gpu/lossless.rs (24 bytes).
#include "gen/attr.glsl"
// Members: `ScanPush` in engine/attr_gpu/gpu_shared.rs.
layout(push_constant, std430) uniform Push { SCAN_PUSH_MEMBERS } push;

shared uint64_t range_sums[gl_WorkGroupSize.x];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint per = (push.blocks + gl_WorkGroupSize.x - 1u) / gl_WorkGroupSize.x;
    uint first = min(t * per, push.blocks);
    uint end = min(first + per, push.blocks);
    LosslessEncWords plans = LosslessEncWords(push.plans);
    uint64_t sum = 0ul;
    for (uint b = first; b < end; b++) {
        sum += uint64_t(plans.w[4u * b + 2u]);
    }
    range_sums[t] = sum;
    barrier();
    for (uint step = 1u; step < gl_WorkGroupSize.x; step <<= 1u) {
        uint64_t add = t >= step ? range_sums[t - step] : 0ul;
        barrier();
        range_sums[t] += add;
        barrier();
    }
    // Blocks 1.. sit after the table of their 2-word offsets: exclusive prefix + table size.
    uint64_t table = 2ul * uint64_t(push.blocks - 1u);
    uint64_t offset = table + range_sums[t] - sum;
    LosslessEncOffsets offsets = LosslessEncOffsets(push.offsets);
    for (uint b = first; b < end; b++) {
        offsets.o[b] = b == 0u ? 0ul : offset;
        offset += uint64_t(plans.w[4u * b + 2u]);
    }
    if (t == gl_WorkGroupSize.x - 1u) {
        offsets.o[push.blocks] = table + range_sums[t];
    }
}
