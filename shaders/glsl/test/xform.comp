#version 460
// Test pass of shaders/glsl/render/xform.glsl (tests/transform.rs): case i applies transform
// i % 48 to input record i / 48 and writes XFORM_TEST_OUT_WORDS words: the leaf (2 words), the
// child mask, the stored octant, the composition with the record's transform, the
// translation (3 words), the record's leaf moved by shift i % 343 (x, y, z in -3..3: i % 7 - 3,
// i / 7 % 7 - 3, i / 49 % 7 - 3; 2 words).
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

#include "render/xform.glsl"

layout(local_size_x = 64) in;

// Per record: leaf low word, leaf high word, then child mask | octant << 8 | transform << 16,
// then the translation's x, y, z as signed bytes.
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer InWords {
    uint w[];
};

layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer OutWords {
    uint w[];
};

#include "gen/test.glsl"
layout(push_constant, std430) uniform Push { DECODE_TEST_PUSH_MEMBERS } push;

#define XFORM_TEST_OUT_WORDS 10u

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= push.count) {
        return;
    }
    uint t = i % 48u;
    InWords record = InWords(push.chunk_addr + 16ul * uint64_t(i / 48u));
    uvec2 leaf = xform_leaf(t, uvec2(record.w[0], record.w[1]));
    uint packed = record.w[2];
    uint tr_word = record.w[3];
    ivec3 tr = ivec3(bitfieldExtract(int(tr_word), 0, 8), bitfieldExtract(int(tr_word), 8, 8),
                     bitfieldExtract(int(tr_word), 16, 8));
    ivec3 seen = xform_translation(t, tr);
    OutWords out_words = OutWords(push.out_addr + 4ul * XFORM_TEST_OUT_WORDS * uint64_t(i));
    out_words.w[0] = leaf.x;
    out_words.w[1] = leaf.y;
    out_words.w[2] = xform_child_mask(t, packed & 0xffu);
    out_words.w[3] = xform_stored_octant(t, (packed >> 8u) & 7u);
    out_words.w[4] = xform_compose(t, (packed >> 16u) & 0xffu);
    out_words.w[5] = uint(seen.x);
    out_words.w[6] = uint(seen.y);
    out_words.w[7] = uint(seen.z);
    uint s = i % 343u;
    ivec3 shift = ivec3(s % 7u, s / 7u % 7u, s / 49u) - 3;
    uvec2 moved = xform_leaf_shift(uvec2(record.w[0], record.w[1]), shift);
    out_words.w[8] = moved.x;
    out_words.w[9] = moved.y;
}
