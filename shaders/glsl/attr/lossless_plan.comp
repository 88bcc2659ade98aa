#version 460
// Lossless colour encoder, pass 1 of 3: one invocation per block plans it (`plan_block` in
// engine/attr/lossless.rs) and writes its two header words and its size in words to
// `plans[4 * block ..]` (fourth word unused). Driven by engine/attr_gpu/lossless.rs.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x_id = 0) in;

#include "attr/lossless_encode.glsl"

// Mirror of `PlanPush` in engine/attr_gpu/lossless.rs (24 bytes).
#include "gen/attr.glsl"
// Members: `PlanPush` in engine/attr_gpu/gpu_shared.rs.
layout(push_constant, std430) uniform Push { PLAN_PUSH_MEMBERS } push;

void main() {
    uint blocks = (push.count + LOSSLESS_BLOCK_COLORS - 1u) / LOSSLESS_BLOCK_COLORS;
    uint b = gl_GlobalInvocationID.x;
    if (b >= blocks) {
        return;
    }
    uint first = b * LOSSLESS_BLOCK_COLORS;
    uint n = min(push.count - first, LOSSLESS_BLOCK_COLORS);
    lossless_load_block(push.colors, first, n, push.variant);
    LosslessPlan p = lossless_plan_block(n, push.variant);
    uvec2 h = lossless_header(p);
    LosslessEncWords plans = LosslessEncWords(push.plans);
    plans.w[4u * b] = h.x;
    plans.w[4u * b + 1u] = h.y;
    plans.w[4u * b + 2u] = lossless_block_words(p);
    plans.w[4u * b + 3u] = 0u;
}
