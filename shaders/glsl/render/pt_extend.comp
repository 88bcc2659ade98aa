#version 460
// Wavefront extend pass: traces the ray of every queued path and stores its hit (sample 0,
// bounce 0 also writes the first-hit buffer).
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
    vec3 origin = paths.p[index].origin.xyz;
    vec3 dir = paths.p[index].dir.xyz;
    traverse_begin(p.root_level);
    Hit h;
    // Sample 0's bounce 0 runs with colour indices (the host's variant): the variant without
    // them compiles the (masked) first-hit write out.
    bool first = PT_COLOR_INDEX && push.bounce == 0u && push.sample_index == 0u &&
                 pt.first_hits != 0ul;
    bool hit = trace_ray_indexed(origin, dir, TRAVERSE_T_UNBOUNDED, p.root_level,
                                 PT_COLOR_INDEX && (first || pt_needs_color_index(p, pt)), h);
    if (first) {
        pt_write_first_hit(pt, index, hit, h);
    }
    paths.p[index].t = h.t;
    paths.p[index].color_index = h.color_index;
    paths.p[index].normal_code = hit ? pt_normal_code(h.normal) : 0u;
}
