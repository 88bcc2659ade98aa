#version 460
// Megakernel path tracer: one invocation runs whole paths, of PT_MEGA_PATHS pixels in turn, for
// one sample (push.sample) and adds each path's radiance to the accumulation buffer; sample 0 also writes the
// first-hit buffer when one is given. Driven by engine/render/pathtrace_gpu.rs; the CPU twin is
// engine/render/pathtrace.rs, the wavefront twin pt_generate/extend/shade/shadow/accumulate.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

// Workgroup size: specialization constants 0 and 1 (8 x 8).
layout(local_size_x_id = 0, local_size_y_id = 1, local_size_z = 1) in;

#include "render/pt_common.glsl"

// Paths each invocation traces one after the other (specialization constant 3, set from
// `PT_MEGA_PATHS` in engine/render/pathtrace_gpu.rs, which sizes the dispatch by it):
// invocation (x, y) takes the pixels (x, PT_MEGA_PATHS * y + k).
// A lane whose path ends starts its next one at once, so the SIMD lanes of a group keep
// tracing rays (path regeneration) where one path per invocation left finished lanes masked
// while the group's longest path went on; every path uses its own pixel's RNG stream, so the
// image does not depend on which invocation traced it (docs/pathtracing.md, "Path
// regeneration in the megakernel").
layout(constant_id = 3) const uint PT_MEGA_PATHS = 4u;

// Specialization constant 4: whether the sun's shadow rays are compiled in. lavapipe runs an
// `if` whose condition no lane meets (masked) and each loop body at least once, so without the
// constant every hit of a sunless render paid for one masked pass through the shadow ray's
// traversal; the host picks the variant by the sun's intensity (docs/pathtracing.md, "Code
// that no path needs").
layout(constant_id = 4) const bool PT_SUN = true;

void main() {
    RenderParams p = PtRenderParamsRef(push.params).params;
    PtParams pt = PtParamsRef(push.pt).pt;
    uvec2 slot = gl_GlobalInvocationID.xy;
    if (slot.x >= p.width || PT_MEGA_PATHS * slot.y >= p.height) {
        return;
    }
    traverse_begin(p.root_level);
    vec3 sun = pt.sun.xyz;
    bool want_color = pt_needs_color_index(p, pt);
    PtAccumRef accum = PtAccumRef(pt.accum);
    // The path being traced: its pixel, RNG key, ray, throughput, radiance and bounce.
    uint started = 0u;
    bool tracing = false;
    uint index = 0u;
    uint key = 0u;
    vec3 origin = vec3(0.0);
    vec3 dir = vec3(0.0);
    vec3 throughput = vec3(1.0);
    precise vec3 radiance = vec3(0.0);
    uint k = 0u;
    for (;;) {
        if (!tracing) {
            uvec2 pixel = uvec2(slot.x, PT_MEGA_PATHS * slot.y + started);
            if (started == PT_MEGA_PATHS || pixel.y >= p.height) {
                break;
            }
            started += 1u;
            index = pixel.y * p.width + pixel.x;
            key = pt_path_key(pt.seed, index, push.sample_index);
            pt_camera_ray(pixel, p, pt_random(key, 0u, 0u), pt_random(key, 0u, 1u), origin, dir);
            throughput = vec3(1.0);
            radiance = vec3(0.0);
            k = 0u;
            tracing = true;
        }
        Hit h;
        // First hits are written by sample 0, which the host always runs with colour indices:
        // the variant without them compiles the (masked) write out.
        bool first = PT_COLOR_INDEX && k == 0u && push.sample_index == 0u && pt.first_hits != 0ul;
        bool hit = trace_ray_indexed(origin, dir, TRAVERSE_T_UNBOUNDED, p.root_level,
                                     PT_COLOR_INDEX && (first || want_color), h);
        if (first) {
            pt_write_first_hit(pt, index, hit, h);
        }
        uint i = k + 1u; // surface interactions so far
        if (!hit) {
            radiance = radiance + throughput * pt.env.xyz;
            tracing = false;
        } else if (i > pt.bounces) {
            tracing = false;
        } else {
            vec3 albedo = pt_albedo(p, pt, h.color_index);
            vec3 start = pt_offset_point(origin, dir, h.t, h.normal, p.up.w);
            if (PT_SUN && pt.sun.w > 0.0) {
                float n_dot_l = pt_n_dot_l(h.normal, sun);
                if (n_dot_l > 0.0) {
                    Hit blocker;
                    if (!trace_ray_indexed(start, sun, TRAVERSE_T_UNBOUNDED, p.root_level,
                                           false, blocker)) {
                        radiance = radiance + pt_sun_contribution(pt, throughput, albedo,
                                                                  n_dot_l);
                    }
                }
            }
            dir = pt_cosine_direction(h.normal, pt_random(key, i, 0u), pt_random(key, i, 1u));
            origin = start;
            precise vec3 t = throughput * albedo;
            throughput = t;
            k = i;
            if (i >= pt.rr_depth && !pt_roulette(throughput, pt_random(key, i, 2u))) {
                tracing = false;
            }
        }
        if (!tracing) {
            precise vec4 sum = accum.v[index] + vec4(radiance, 1.0);
            accum.v[index] = sum;
        }
    }
}
