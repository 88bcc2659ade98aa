// The cube's transform group (engine/dag/transform.rs) computed with integer arithmetic, for
// the traversal of the transformed formats (dag_formats.glsl) and its GPU test
// (test/xform.comp, tests/transform.rs: equal to `Transform` for all 48 transforms).
// Arithmetic rather than tables in the info block: measured when the info block was read
// through a buffer address, which lavapipe loads one SIMD lane at a time, these vector
// operations cost far less (docs/pathtracing.md, "Where the time goes on lavapipe"); not
// measured again since the info block became a texel buffer (a gather per read).
// Transform t = 8 * permutation + mirror bits; output axis i reads input axis
// `PERMUTATIONS[t >> 3][i]`, then mirror bit i flips it.
#ifndef VOXDAG_RENDER_XFORM_GLSL
#define VOXDAG_RENDER_XFORM_GLSL

// Output axis i of transform t reads input axis `xform_axis(t, i)` (2 bits per permutation).
uint xform_axis(uint t, uint i) {
    uint packed = i == 0u ? 0xa50u : (i == 1u ? 0x489u : 0x126u);
    return (packed >> (2u * (t >> 3u))) & 3u;
}

// The octant bits o permuted by t's permutation (no mirror).
uint xform_permute_bits(uint t, uint o) {
    return ((o >> xform_axis(t, 0u)) & 1u) | (((o >> xform_axis(t, 1u)) & 1u) << 1u) |
           (((o >> xform_axis(t, 2u)) & 1u) << 2u);
}

// The stored octant s that t moves to world octant c (`t.inverse().apply_octant(c)`).
uint xform_stored_octant(uint t, uint c) {
    uint x = c ^ (t & 7u);
    return ((x & 1u) << xform_axis(t, 0u)) | (((x >> 1u) & 1u) << xform_axis(t, 1u)) |
           (((x >> 2u) & 1u) << xform_axis(t, 2u));
}

// `a ∘ b` (`Transform::compose`): b first, then a.
uint xform_compose(uint a, uint b) {
    uint c0 = xform_axis(b, xform_axis(a, 0u));
    uint c1 = xform_axis(b, xform_axis(a, 1u));
    uint c2 = xform_axis(b, xform_axis(a, 2u));
    uint perm = 2u * c0 + (c1 > c2 ? 1u : 0u);
    return 8u * perm + ((a & 7u) ^ xform_permute_bits(a, b & 7u));
}

// Masks and leaves are transformed by delta swaps (exchange the bits selected by a mask with
// those `shift` above them) on 32-bit words, without branches: lavapipe runs both sides of a
// branch anyway, and a 64-bit operation is two on its 8-wide vectors. A delta swap whose mask
// is zero changes nothing, so each step takes its mask from one bit of t (`xform_when`).
// Permutation p of the index bits (x, y, z) is the transpositions (x y), (y z), (x y) in turn,
// each where bit p of 0x2c, 0x3a and 0x30 is set (p = 5, (x z), takes all three); the mirror
// of axis i then flips index bit i.
#define XFORM_STEP_XY_FIRST 0x2cu
#define XFORM_STEP_YZ 0x3au
#define XFORM_STEP_XY_LAST 0x30u

// All ones where bit i of bits is set, else zero.
uint xform_when(uint bits, uint i) {
    return 0u - ((bits >> i) & 1u);
}

uvec2 xform_delta_swap(uvec2 x, uint mask, uint shift) {
    uvec2 d = ((x >> shift) ^ x) & uvec2(mask);
    return x ^ d ^ (d << shift);
}

// Every byte of h, read as an 8-bit child mask (bit = octant), seen through t: the bits of the
// octant index inside each byte permuted, then mirrored.
uvec2 xform_in_bytes(uint t, uvec2 h) {
    uint p = t >> 3u;
    h = xform_delta_swap(h, xform_when(XFORM_STEP_XY_FIRST, p) & 0x22222222u, 1u);
    h = xform_delta_swap(h, xform_when(XFORM_STEP_YZ, p) & 0x0c0c0c0cu, 2u);
    h = xform_delta_swap(h, xform_when(XFORM_STEP_XY_LAST, p) & 0x22222222u, 1u);
    h = xform_delta_swap(h, xform_when(t, 0u) & 0x55555555u, 1u);
    h = xform_delta_swap(h, xform_when(t, 1u) & 0x33333333u, 2u);
    return xform_delta_swap(h, xform_when(t, 2u) & 0x0f0f0f0fu, 4u);
}

// The 8 bytes of h (byte o = octant o: bytes 0-3 in h.x, 4-7 in h.y) moved to their octants
// seen through t; the bits inside each byte stay.
uvec2 xform_bytes(uint t, uvec2 h) {
    uint p = t >> 3u;
    h = xform_delta_swap(h, xform_when(XFORM_STEP_XY_FIRST, p) & 0x0000ff00u, 8u);
    // (y z): the upper half of the low word with the lower half of the high word.
    uint cross = ((h.y << 16u) ^ h.x) & (xform_when(XFORM_STEP_YZ, p) & 0xffff0000u);
    h = uvec2(h.x ^ cross, h.y ^ (cross >> 16u));
    h = xform_delta_swap(h, xform_when(XFORM_STEP_XY_LAST, p) & 0x0000ff00u, 8u);
    h = xform_delta_swap(h, xform_when(t, 0u) & 0x00ff00ffu, 8u);
    h = xform_delta_swap(h, xform_when(t, 1u) & 0x0000ffffu, 16u);
    return (t & 4u) != 0u ? h.yx : h;
}

// An 8-bit child mask (bit o = octant o) seen through t (`Transform::apply_child_mask`).
uint xform_child_mask(uint t, uint mask) {
    return xform_in_bytes(t, uvec2(mask, 0u)).x;
}

// A 4^3 leaf mask (bit = Morton code: sub-block octant << 3 | voxel octant) seen through t
// (`Transform::apply_leaf`): the voxels inside each sub-block, then the sub-blocks.
uvec2 xform_leaf(uint t, uvec2 bits) {
    return xform_bytes(t, xform_in_bytes(t, bits));
}

// Picks component `axis` of v. Selects rather than `v[axis]`: a vector indexed by a value
// lavapipe cannot fold costs several times more (docs/pathtracing.md).
int xform_pick(ivec3 v, uint axis) {
    return axis == 0u ? v.x : (axis == 1u ? v.y : v.z);
}

// `T(Shift_tr(X)) = Shift_tr'(T(X))`: the translation tr' seen through t.
ivec3 xform_translation(uint t, ivec3 tr) {
    ivec3 v = ivec3(xform_pick(tr, xform_axis(t, 0u)), xform_pick(tr, xform_axis(t, 1u)),
                    xform_pick(tr, xform_axis(t, 2u)));
    return mix(v, -v, notEqual(uvec3(t) & uvec3(1u, 2u, 4u), uvec3(0u)));
}

// The voxels of a 4^3 leaf (bits as in `xform_leaf`) moved by t along the axis whose
// coordinate has its low bit at index bit `a` and its high bit at index bit a + 3 (x: a = 0,
// y: a = 1; both inside each word), `low` / `high` the voxels with that bit set; |t| <= 3,
// voxels moved out of the leaf dropped. A step of 1 moves coordinates 0 <-> 1 and 2 <-> 3 by
// 1 << a and 1 <-> 2 by 7 << a, a step of 2 moves them by 8 << a; t = +-3 is a step of 1 then
// one of 2 the same way (no voxel leaves and comes back).
uvec2 xform_leaf_move(uvec2 m, uint a, uint low, uint high, int t) {
    uint u = 1u << a;
    uint h = 8u << a;
    uvec2 plus1 = ((m & ~low) << u) | ((m & (low & ~high)) << (h - u));
    uvec2 minus1 = ((m & low) >> u) | ((m & (~low & high)) >> (h - u));
    uvec2 odd = (t & 1) == 0 ? m : (t > 0 ? plus1 : minus1);
    uvec2 two = t > 0 ? (odd & ~high) << h : (odd & high) >> h;
    return abs(t) >= 2 ? two : odd;
}

// The same along z, whose low bit is index bit 2 and whose high bit picks the word.
uvec2 xform_leaf_move_z(uvec2 m, int t) {
    const uint low = 0xf0f0f0f0u;
    uvec2 plus1 = uvec2((m.x & ~low) << 4u, ((m.y & ~low) << 4u) | ((m.x & low) >> 4u));
    uvec2 minus1 = uvec2(((m.x & low) >> 4u) | ((m.y & ~low) << 4u), (m.y & low) >> 4u);
    uvec2 odd = (t & 1) == 0 ? m : (t > 0 ? plus1 : minus1);
    uvec2 two = t > 0 ? uvec2(0u, odd.x) : uvec2(odd.y, 0u);
    return abs(t) >= 2 ? two : odd;
}

// A leaf's world bits under the destructive translation tr (|tr| <= 3 per axis): voxel p
// moves to p + tr, voxels leaving the 4^3 cell are dropped (`TsvdagEncoding::materialise`).
uvec2 xform_leaf_shift(uvec2 bits, ivec3 tr) {
    bits = xform_leaf_move(bits, 0u, 0xaaaaaaaau, 0xff00ff00u, tr.x);
    bits = xform_leaf_move(bits, 1u, 0xccccccccu, 0xffff0000u, tr.y);
    return xform_leaf_move_z(bits, tr.z);
}

#endif
