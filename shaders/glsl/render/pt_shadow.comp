#version 460
// Wavefront shadow pass: traces every queued sun shadow ray; an unoccluded one adds its
// contribution to its pixel's path radiance (one path per pixel: no two rays of a pass share one).
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 64) in;

#include "render/pt_wave.glsl"

void main() {
    RenderParams p = PtRenderParamsRef(push.params).params;
    PtParams pt = PtParamsRef(push.pt).pt;
    uint slot = pt_wave_slot();
    if (slot >= PtQueueRef(pt.shadow_count).v[0]) {
        return;
    }
    PtShadowRay ray = PtShadowsRef(pt.shadow_queue).r[slot];
    traverse_begin(p.root_level);
    Hit blocker;
    if (!trace_ray_indexed(ray.origin.xyz, pt.sun.xyz, TRAVERSE_T_UNBOUNDED, p.root_level, false,
                           blocker)) {
        uint index = floatBitsToUint(ray.origin.w);
        PtPathsRef paths = PtPathsRef(pt.paths);
        precise vec3 r = paths.p[index].radiance.xyz + ray.contribution.xyz;
        paths.p[index].radiance = vec4(r, 0.0);
    }
}
