// Path tracing: what the megakernel (pt_mega.comp) and the wavefront passes (pt_generate,
// pt_extend, pt_shade, pt_shadow, pt_accumulate) share. The GLSL twin of
// engine/render/pathtrace.rs (CPU reference): counter-based RNG, jittered camera rays,
// cosine-weighted hemisphere sampling, Lambertian albedo, sun next-event estimation, Russian
// roulette. Every float step that feeds a value or a decision is `precise` and in the CPU's
// order, so that on a driver with correctly rounded division and sqrt (lavapipe) the CPU
// reference reproduces the GPU's paths bit for bit (docs/pathtracing.md).
//
// The includer declares nothing: this file declares the push constant block (`PtPush`), the
// buffer references and the DAG accessors (`dag_word`, `dag_node_voxels`; `dag_info` from
// dag_tables.glsl at binding 0), then includes colors.glsl and traverse.glsl (so every pt
// shader has one variant per DAG format).
#ifndef VOXDAG_RENDER_PT_COMMON_GLSL
#define VOXDAG_RENDER_PT_COMMON_GLSL

#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

#include "shared/render_params.h"

struct PtParams {
    PT_PARAMS_MEMBERS
};

struct FirstHit {
    FIRST_HIT_MEMBERS
};

// Members: `PtPush` in engine/render/gpu_shared.rs.
layout(push_constant, std430) uniform Push { PT_PUSH_MEMBERS } push;

// Specialization constant 2: whether the pipeline computes colour indices at all. The host
// dispatches a variant without them (`false`) for the samples and bounces that read none (no
// first-hit buffer to fill, an albedo that does not read voxel colours): lavapipe runs the
// colour-index code after every traversal, masked, even when no invocation wants it
// (docs/pathtracing.md, "Where the time goes on lavapipe").
layout(constant_id = 2) const bool PT_COLOR_INDEX = true;

layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer PtRenderParamsRef {
    RenderParams params;
};
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer PtParamsRef {
    PtParams pt;
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer PtWordsRef {
    uint w[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer PtWords64Ref {
    uint64_t w[];
};
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer PtLutRef {
    float v[];
};
layout(buffer_reference, std430, buffer_reference_align = 16) buffer PtAccumRef {
    vec4 v[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) writeonly buffer PtFirstHitsRef {
    FirstHit h[];
};

uint dag_word(uint i) {
    return PtWordsRef(push.words).w[i];
}

// Words i and i + 1 as one 64-bit load (4-byte aligned: x86 lavapipe and GPUs load it as two
// words' worth; one per-lane loop on lavapipe instead of two).
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer PtWordPairRef {
    uint64_t v;
};

#define DAG_HAS_WORD_PAIR 1
uvec2 dag_word_pair(uint i) {
    return unpackUint2x32(PtWordPairRef(push.words + 4ul * uint64_t(i)).v);
}

#define DAG_TABLES_BINDING 0
#include "render/dag_tables.glsl"

uint64_t dag_node_voxels(uint i) {
    return PtWords64Ref(push.node_voxels).w[i];
}

#include "render/colors.glsl"
#include "render/traverse.glsl"

// f32 constants by bit pattern (no decimal parsing differences with the CPU).
#define PT_INV_PI uintBitsToFloat(0x3ea2f983u)   // 1 / pi
#define PT_HALF_PI uintBitsToFloat(0x3fc90fdbu)  // pi / 2
#define PT_INV_2_24 uintBitsToFloat(0x33800000u) // 2^-24
#define PT_RR_MAX uintBitsToFloat(0x3f733333u)   // 0.95

// PCG hash (Jarzynski & Olano 2020, "Hash Functions for GPU Rendering"): a bijection of u32.
uint pt_pcg(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Key of one path: pcg(pcg(pcg(seed) ^ pixel) ^ sample).
uint pt_path_key(uint seed, uint pixel, uint sample_index) {
    return pt_pcg(pt_pcg(pt_pcg(seed) ^ pixel) ^ sample_index);
}

// Uniform number in [0, 1) (multiples of 2^-24) for dimension `dim` (0..3) of bounce `bounce`
// (0: the camera ray, i: the i-th surface interaction).
float pt_random(uint key, uint bounce, uint dim) {
    uint h = pt_pcg(key ^ pt_pcg(bounce * 4u + dim));
    return float(h >> 8u) * PT_INV_2_24;
}

// sin and cos of a in [0, pi/2): Taylor polynomials (degree 11 / 12, error < 4e-8), Horner in a^2.
void pt_sincos(float a, out float s, out float c) {
    precise float a2 = a * a;
    precise float ps = uintBitsToFloat(0xb2d7322bu); // -1/39916800
    ps = ps * a2 + uintBitsToFloat(0x3638ef1du);     // 1/362880
    ps = ps * a2 + uintBitsToFloat(0xb9500d01u);     // -1/5040
    ps = ps * a2 + uintBitsToFloat(0x3c088889u);     // 1/120
    ps = ps * a2 + uintBitsToFloat(0xbe2aaaabu);     // -1/6
    ps = ps * a2 + 1.0;
    s = ps * a;
    precise float pc = uintBitsToFloat(0x310f76c7u); // 1/479001600
    pc = pc * a2 + uintBitsToFloat(0xb493f27eu);     // -1/3628800
    pc = pc * a2 + uintBitsToFloat(0x37d00d01u);     // 1/40320
    pc = pc * a2 + uintBitsToFloat(0xbab60b61u);     // -1/720
    pc = pc * a2 + uintBitsToFloat(0x3d2aaaabu);     // 1/24
    pc = pc * a2 + -0.5;
    c = pc * a2 + 1.0;
}

// Cosine-weighted direction around the axis-aligned normal `n` (Malley: uniform disk point
// lifted to the hemisphere). The disk angle 2 pi u2 is split into a quadrant and an angle in
// [0, pi/2); the tangent frame of an axis normal is a permutation of the axes (exact).
vec3 pt_cosine_direction(ivec3 n, float u1, float u2) {
    precise float r = sqrt(u1);
    precise float x4 = 4.0 * u2;
    uint q = uint(x4);
    precise float f = x4 - float(q);
    precise float a = f * PT_HALF_PI;
    float s;
    float c;
    pt_sincos(a, s, c);
    float dx = c;
    float dy = s;
    if (q == 1u) {
        dx = -s;
        dy = c;
    } else if (q == 2u) {
        dx = -c;
        dy = -s;
    } else if (q == 3u) {
        dx = s;
        dy = -c;
    }
    precise float lx = r * dx;
    precise float ly = r * dy;
    precise float lz = sqrt(1.0 - u1);
    uint axis = n.x != 0 ? 0u : (n.y != 0 ? 1u : 2u);
    vec3 d;
    d[axis] = n[axis] > 0 ? lz : -lz;
    d[(axis + 1u) % 3u] = lx;
    d[(axis + 2u) % 3u] = ly;
    return d;
}

// Camera ray through pixel + (jx, jy), jx, jy in [0, 1) (`RenderParams::primary_ray` at the
// pixel centre for jx = jy = 0.5).
void pt_camera_ray(uvec2 pixel, RenderParams p, float jx, float jy, out vec3 origin,
                   out vec3 dir) {
    precise float px = float(pixel.x) + jx;
    precise float py = float(pixel.y) + jy;
    precise float u = (px - 0.5 * float(p.width)) * p.right.w;
    precise float v = (0.5 * float(p.height) - py) * p.right.w;
    precise vec3 d = (p.forward.xyz + u * p.right.xyz) + v * p.up.xyz;
    origin = p.eye.xyz;
    dir = d;
}

// Whether `pt_albedo` reads the hit's colour index (a coloured scene without a uniform albedo;
// `PtTarget::needs_color_index` on the host).
bool pt_needs_color_index(RenderParams p, PtParams pt) {
    return PT_COLOR_INDEX && pt.env.w < 0.0 && (p.flags & RENDER_FLAG_HAS_COLORS) != 0u;
}

// Linear albedo of a hit: the uniform albedo (pt.env.w >= 0), the voxel's colour through the
// sRGB -> linear table, or grey 0.6 without colours (like the raster shading). A variant
// without colour indices (PT_COLOR_INDEX false) serves only renders that read no voxel colour
// (the host's `needs_color_index`), so it compiles the colour decode out: lavapipe would run
// its chunk search masked after every hit.
vec3 pt_albedo(RenderParams p, PtParams pt, uint64_t color_index) {
    if (pt.env.w >= 0.0) {
        return vec3(pt.env.w);
    }
    if (!PT_COLOR_INDEX || (p.flags & RENDER_FLAG_HAS_COLORS) == 0u) {
        return vec3(uintBitsToFloat(0x3f19999au)); // 0.6
    }
    uint rgba = color_index < p.color_count ? chunk_color(color_index) : 0xffffffffu;
    PtLutRef lut = PtLutRef(pt.srgb_lut);
    return vec3(lut.v[rgba & 0xffu], lut.v[(rgba >> 8u) & 0xffu], lut.v[(rgba >> 16u) & 0xffu]);
}

// Hit normal as a code: 0 = no hit, 1 + 2 axis + (normal negative ? 1 : 0).
uint pt_normal_code(ivec3 n) {
    uint axis = n.x != 0 ? 0u : (n.y != 0 ? 1u : 2u);
    return 1u + 2u * axis + (n[axis] < 0 ? 1u : 0u);
}

ivec3 pt_normal_of(uint code) {
    ivec3 n = ivec3(0);
    uint axis = (code - 1u) >> 1u;
    n[axis] = (code & 1u) == 0u ? -1 : 1;
    return n;
}

// Writes the first hit of pixel `index` (`render::FirstHit`, as primary.comp: all zero on a miss).
void pt_write_first_hit(PtParams pt, uint index, bool hit, Hit h) {
    FirstHit f;
    f.hit = hit ? 1u : 0u;
    f.t_bits = hit ? floatBitsToUint(h.t) : 0u;
    for (uint k = 0u; k < 3u; k++) {
        f.voxel[k] = hit ? h.voxel[k] : 0u;
        f.normal[k] = hit ? h.normal[k] : 0;
    }
    f.color_index = hit ? h.color_index : 0ul;
    PtFirstHitsRef(pt.first_hits).h[index] = f;
}

// Next-event estimation towards the sun from a surface point: the radiance the sun adds through
// this interaction when unoccluded, (throughput * albedo) * (intensity * n.L / pi).
vec3 pt_sun_contribution(PtParams pt, vec3 throughput, vec3 albedo, float n_dot_l) {
    precise float e = (pt.sun.w * n_dot_l) * PT_INV_PI;
    precise vec3 c = (throughput * albedo) * e;
    return c;
}

// n . sun for an axis normal.
float pt_n_dot_l(ivec3 n, vec3 l) {
    vec3 nf = vec3(n);
    precise float d = nf.x * l.x + nf.y * l.y + nf.z * l.z;
    return d;
}

// The point a secondary or shadow ray starts from: (origin + t dir) + n eps (`shade.glsl`'s
// shadow origin).
vec3 pt_offset_point(vec3 origin, vec3 dir, float t, ivec3 n, float eps) {
    precise vec3 o = (origin + t * dir) + vec3(n) * eps;
    return o;
}

// Russian roulette at interaction i >= rr_depth: survive with p = min(max channel, 0.95), then
// divide by p. Returns false when the path ends.
bool pt_roulette(inout vec3 throughput, float u) {
    float p = min(max(max(throughput.x, throughput.y), throughput.z), PT_RR_MAX);
    if (u >= p) {
        return false;
    }
    precise vec3 t = throughput / p;
    throughput = t;
    return true;
}

#endif
