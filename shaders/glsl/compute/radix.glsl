// LSD radix sort (engine/compute/sort.rs): key type, digits and push constants shared by the
// histogram and scatter passes. Define KEY64 (0 or 1) before including. Specialization constant
// 2 = digit bits (4 or 8); a pass sorts by the digit at bit `shift`.
#include "compute/common.glsl"

layout(constant_id = 2) const uint BITS = 8;
const uint BINS = 1u << BITS;

#if KEY64
#define KEY_T uint64_t
#define KEYS_T U64s
#define KEY_MAX 0xfffffffffffffffful
#else
#define KEY_T uint
#define KEYS_T U32s
#define KEY_MAX 0xffffffffu
#endif

// Mirror of `RadixPush` in engine/compute/sort.rs (56 bytes). `offsets` is the histogram
// (hist pass output) or its exclusive scan (scatter pass input), digit-major: [digit * tiles + tile].
#include "gen/compute.glsl"
// Members: `RadixPush` in engine/compute/gpu_shared.rs.
layout(push_constant, std430) uniform Push { RADIX_PUSH_MEMBERS } push;

uint digit_of(KEY_T key) {
    return uint(key >> push.shift) & (BINS - 1u);
}

uint tile_count() {
    return (push.n + BLOCK - 1u) / BLOCK;
}
