#version 460
// Wavefront accumulate pass: adds each pixel's path radiance of this sample to the accumulation
// buffer (as pt_mega.comp does at the end of its path).
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 64) in;

#include "render/pt_wave.glsl"

void main() {
    PtParams pt = PtParamsRef(push.pt).pt;
    uint index = pt_wave_slot();
    if (index >= pt.pixels) {
        return;
    }
    PtAccumRef accum = PtAccumRef(pt.accum);
    precise vec4 sum = accum.v[index] + vec4(PtPathsRef(pt.paths).p[index].radiance.xyz, 1.0);
    accum.v[index] = sum;
}
