#version 460
// Megakernel path tracer: one invocation runs the whole path of its pixel for one sample
// (push.sample) and adds the radiance to the accumulation buffer; sample 0 also writes the
// first-hit buffer when one is given. Driven by engine/render/pathtrace_gpu.rs; the CPU twin is
// engine/render/pathtrace.rs, the wavefront twin pt_generate/extend/shade/shadow/accumulate.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

// Workgroup size: specialization constants 0 and 1 (8 x 8).
layout(local_size_x_id = 0, local_size_y_id = 1, local_size_z = 1) in;

#include "render/pt_common.glsl"

void main() {
    RenderParams p = PtRenderParamsRef(push.params).params;
    PtParams pt = PtParamsRef(push.pt).pt;
    uvec2 pixel = gl_GlobalInvocationID.xy;
    if (pixel.x >= p.width || pixel.y >= p.height) {
        return;
    }
    uint index = pixel.y * p.width + pixel.x;
    uint key = pt_path_key(pt.seed, index, push.sample_index);
    vec3 origin;
    vec3 dir;
    pt_camera_ray(pixel, p, pt_random(key, 0u, 0u), pt_random(key, 0u, 1u), origin, dir);
    traverse_begin(p.root_level);
    vec3 throughput = vec3(1.0);
    precise vec3 radiance = vec3(0.0);
    vec3 sun = pt.sun.xyz;
    bool want_color = pt_needs_color_index(p, pt);
    for (uint k = 0u; k <= pt.bounces; k++) {
        Hit h;
        bool first = k == 0u && push.sample_index == 0u && pt.first_hits != 0ul;
        bool hit = trace_ray_indexed(origin, dir, TRAVERSE_T_UNBOUNDED, p.root_level,
                                     PT_COLOR_INDEX && (first || want_color), h);
        if (first) {
            pt_write_first_hit(pt, index, hit, h);
        }
        if (!hit) {
            radiance = radiance + throughput * pt.env.xyz;
            break;
        }
        uint i = k + 1u; // surface interactions so far
        if (i > pt.bounces) {
            break;
        }
        vec3 albedo = pt_albedo(p, pt, h.color_index);
        vec3 start = pt_offset_point(origin, dir, h.t, h.normal, p.up.w);
        if (pt.sun.w > 0.0) {
            float n_dot_l = pt_n_dot_l(h.normal, sun);
            if (n_dot_l > 0.0) {
                Hit blocker;
                if (!trace_ray_indexed(start, sun, TRAVERSE_T_UNBOUNDED, p.root_level, false,
                                       blocker)) {
                    radiance = radiance + pt_sun_contribution(pt, throughput, albedo, n_dot_l);
                }
            }
        }
        dir = pt_cosine_direction(h.normal, pt_random(key, i, 0u), pt_random(key, i, 1u));
        origin = start;
        precise vec3 t = throughput * albedo;
        throughput = t;
        if (i >= pt.rr_depth && !pt_roulette(throughput, pt_random(key, i, 2u))) {
            break;
        }
    }
    PtAccumRef accum = PtAccumRef(pt.accum);
    precise vec4 sum = accum.v[index] + vec4(radiance, 1.0);
    accum.v[index] = sum;
}
