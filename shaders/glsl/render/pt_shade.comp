#version 460
// Wavefront shade pass (bounce push.bounce): escaped paths add the environment; hits past the
// bounce limit end; the others queue a sun shadow ray (atomic append), sample their next
// direction, apply Russian roulette and raise their survival flag for the compaction that
// builds the next extension queue. Same steps and arithmetic as one loop turn of pt_mega.comp.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 64) in;

#include "render/pt_wave.glsl"

void main() {
    RenderParams p = PtRenderParamsRef(push.params).params;
    PtParams pt = PtParamsRef(push.pt).pt;
    uint slot = pt_wave_slot();
    if (slot >= PtQueueRef(pt.ext_count).v[0]) {
        return;
    }
    uint index = PtQueueRef(pt_queue_in(pt)).v[slot];
    PtPathsRef paths = PtPathsRef(pt.paths);
    PtPath path = paths.p[index];
    vec3 throughput = path.throughput.xyz;
    uint alive = 0u;
    if (path.normal_code == 0u) {
        precise vec3 r = path.radiance.xyz + throughput * pt.env.xyz;
        paths.p[index].radiance = vec4(r, 0.0);
    } else if (push.bounce + 1u <= pt.bounces) {
        uint i = push.bounce + 1u;
        uint key = pt_path_key(pt.seed, index, push.sample_index);
        ivec3 n = pt_normal_of(path.normal_code);
        vec3 albedo = pt_albedo(p, pt, path.color_index);
        vec3 start = pt_offset_point(path.origin.xyz, path.dir.xyz, path.t, n, p.up.w);
        if (pt.sun.w > 0.0) {
            float n_dot_l = pt_n_dot_l(n, pt.sun.xyz);
            if (n_dot_l > 0.0) {
                uint s = atomicAdd(PtQueueRef(pt.shadow_count).v[0], 1u);
                PtShadowRay ray;
                ray.origin = vec4(start, uintBitsToFloat(index));
                ray.contribution = vec4(pt_sun_contribution(pt, throughput, albedo, n_dot_l), 0.0);
                PtShadowsRef(pt.shadow_queue).r[s] = ray;
            }
        }
        vec3 dir = pt_cosine_direction(n, pt_random(key, i, 0u), pt_random(key, i, 1u));
        precise vec3 t = throughput * albedo;
        throughput = t;
        if (i < pt.rr_depth || pt_roulette(throughput, pt_random(key, i, 2u))) {
            alive = 1u;
            paths.p[index].origin = vec4(start, 0.0);
            paths.p[index].dir = vec4(dir, 0.0);
            paths.p[index].throughput = vec4(throughput, 0.0);
        }
    }
    PtQueueRef(pt.flags).v[slot] = alive;
}
