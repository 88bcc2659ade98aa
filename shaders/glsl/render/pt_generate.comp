#version 460
// Wavefront generate pass: one invocation per pixel builds the jittered camera ray of sample
// push.sample_index (as pt_mega.comp), resets the path and fills extension queue A with every
// pixel; invocation 0 writes the queue's count.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 64) in;

#include "render/pt_wave.glsl"

void main() {
    RenderParams p = PtRenderParamsRef(push.params).params;
    PtParams pt = PtParamsRef(push.pt).pt;
    uint index = pt_wave_slot();
    if (index >= pt.pixels) {
        return;
    }
    uvec2 pixel = uvec2(index % p.width, index / p.width);
    uint key = pt_path_key(pt.seed, index, push.sample_index);
    vec3 origin;
    vec3 dir;
    pt_camera_ray(pixel, p, pt_random(key, 0u, 0u), pt_random(key, 0u, 1u), origin, dir);
    PtPath path;
    path.origin = vec4(origin, 0.0);
    path.dir = vec4(dir, 0.0);
    path.throughput = vec4(1.0, 1.0, 1.0, 0.0);
    path.radiance = vec4(0.0);
    path.color_index = 0ul;
    path.t = 0.0;
    path.normal_code = 0u;
    PtPathsRef(pt.paths).p[index] = path;
    PtQueueRef(pt.queue_a).v[index] = index;
    if (index == 0u) {
        PtQueueRef(pt.ext_count).v[0] = pt.pixels;
    }
}
