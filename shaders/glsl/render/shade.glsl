// Primary rays, shading, shadow ray and sky: the GLSL twin of engine/render/cpu.rs.
//
// The includer defines `dag_word`, `dag_node_voxels` (see traverse.glsl) and
//   uint dag_color(uint64_t i); // RGBA8 colour i (r | g << 8 | b << 16 | a << 24, sRGB)
// before including this file; this file includes traverse.glsl and shared/render_params.h.
// Provides
//   vec4 shade_pixel_hit(uvec2 pixel, RenderParams p, bool want_color, bool shadows,
//                        out bool hit, out Hit h);
// returning the sRGB-encoded colour in [0, 1] (alpha 1) and whether the primary ray hit a voxel.
#ifndef VOXDAG_RENDER_SHADE_GLSL
#define VOXDAG_RENDER_SHADE_GLSL

#include "shared/render_params.h"
#include "render/traverse.glsl"
#include "render/preview.glsl"
#include "render/srgb.glsl"

// Constants of engine/render/cpu.rs.
const float SHADE_AMBIENT = 0.25;
const vec3 SHADE_AMBIENT_AXIS = vec3(0.85, 1.0, 0.7);
const float SHADE_DIFFUSE = 0.75;
const float SHADE_GREY = 0.6;
const vec3 SHADE_SKY_HORIZON = vec3(0.75, 0.82, 0.9);
const vec3 SHADE_SKY_ZENITH = vec3(0.22, 0.42, 0.78);
const vec3 SHADE_SKY_GROUND = vec3(0.32, 0.3, 0.28);

// Linear sky colour along `dir` (not necessarily normalised).
vec3 shade_sky(vec3 dir) {
    float len = sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
    float y = len > 0.0 ? dir.y / len : 0.0;
    vec3 far_c = y >= 0.0 ? SHADE_SKY_ZENITH : SHADE_SKY_GROUND;
    float s = min(abs(y), 1.0);
    return SHADE_SKY_HORIZON + (far_c - SHADE_SKY_HORIZON) * s;
}

// Primary ray through the centre of `pixel` (`RenderParams::primary_ray`): exact same f32 ops.
void shade_primary_ray(uvec2 pixel, RenderParams p, out vec3 origin, out vec3 dir) {
    precise float u = (float(pixel.x) + 0.5 - 0.5 * float(p.width)) * p.right.w;
    precise float v = (0.5 * float(p.height) - float(pixel.y) - 0.5) * p.right.w;
    precise vec3 d = (p.forward.xyz + u * p.right.xyz) + v * p.up.xyz;
    origin = p.eye.xyz;
    dir = d;
}

// The shaded colour of `pixel` and the primary ray's hit (valid when `hit`). `want_color`
// false leaves the hit's colour index out (a scene without colours, no first hits to write)
// and `shadows` false the shadow ray; pass constants (primary.comp's specialization
// constants) so that the code left out is compiled out: lavapipe would run it masked.
vec4 shade_pixel_hit(uvec2 pixel, RenderParams p, bool want_color, bool shadows, out bool hit,
                     out Hit h) {
    vec3 origin;
    vec3 dir;
    shade_primary_ray(pixel, p, origin, dir);
    hit = trace_ray_indexed(origin, dir, TRAVERSE_T_UNBOUNDED, p.root_level, want_color, h);
    if (!hit) {
        return shade_encode(shade_sky(dir));
    }
    vec3 albedo = vec3(SHADE_GREY);
    if (want_color && (p.flags & RENDER_FLAG_HAS_COLORS) != 0u) {
        // Out-of-range indices shade white, like the CPU.
        uint rgba = h.color_index < p.color_count ? dag_color(h.color_index) : 0xffffffffu;
        for (uint k = 0u; k < 3u; k++) {
            albedo[k] = shade_srgb_to_linear(float((rgba >> (8u * k)) & 0xffu) / 255.0);
        }
    }
    vec3 n = vec3(h.normal);
    uint axis = h.normal.x != 0 ? 0u : (h.normal.y != 0 ? 1u : 2u);
    vec3 light = p.light_dir.xyz;
    precise float n_dot_l = max(n.x * light.x + n.y * light.y + n.z * light.z, 0.0);
    precise float direct = SHADE_DIFFUSE * n_dot_l;
    if (shadows && (p.flags & RENDER_FLAG_SHADOWS) != 0u && n_dot_l > 0.0) {
        // Shadow ray from the hit point, pushed off the face by p.up.w along the normal.
        precise vec3 shadow_origin = (origin + h.t * dir) + n * p.up.w;
        Hit blocker;
        if (trace_ray_indexed(shadow_origin, light, TRAVERSE_T_UNBOUNDED, p.root_level, false,
                              blocker)) {
            direct = 0.0;
        }
    }
    precise float light_sum = SHADE_AMBIENT * SHADE_AMBIENT_AXIS[axis] + direct;
    vec3 c = albedo * light_sum;
    if (p.preview_shape != 0u) {
        c = preview_tint(c, h.voxel, p.preview, p.preview_color, p.preview_shape);
    }
    return shade_encode(c);
}

#endif
