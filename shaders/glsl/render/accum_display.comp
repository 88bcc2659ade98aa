#version 460
// Shows a progressive path-traced render (the editor's path-tracing mode): each pixel's mean
// radiance (accumulation / samples), with the brush preview tint on its first hit, sRGB-encoded
// into the storage image; the first hits are copied to a host-visible buffer (the editor reads
// the one under the cursor). The GLSL twin of `pt_view::display_cpu` (engine/render/pt_view.rs).
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require

layout(local_size_x = 8, local_size_y = 8, local_size_z = 1) in;

layout(set = 0, binding = 0, rgba8) uniform writeonly image2D out_image;

#include "gen/render.glsl"
#include "render/preview.glsl"
#include "render/srgb.glsl"

struct FirstHit {
    FIRST_HIT_MEMBERS
};

// Members: `PtDisplayPush` in engine/render/gpu_shared.rs.
layout(push_constant, std430) uniform Push { PT_DISPLAY_PUSH_MEMBERS } push;

layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer AccumRef {
    vec4 v[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer HitsInRef {
    FirstHit h[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) writeonly buffer HitsOutRef {
    FirstHit h[];
};

void main() {
    uvec2 pixel = gl_GlobalInvocationID.xy;
    if (pixel.x >= push.width || pixel.y >= push.height) {
        return;
    }
    uint i = pixel.y * push.width + pixel.x;
    FirstHit f = HitsInRef(push.first_hits).h[i];
    // `PtImage::linear`: the sum times 1 / spp.
    precise float inv = 1.0 / float(max(push.spp, 1u));
    precise vec3 c = AccumRef(push.accum).v[i].rgb * inv;
    if (f.hit != 0u && push.preview_shape != 0u) {
        uvec3 v = uvec3(f.voxel[0], f.voxel[1], f.voxel[2]);
        c = preview_tint(c, v, push.preview, push.preview_color, push.preview_shape);
    }
    imageStore(out_image, ivec2(pixel), shade_encode(c));
    if (push.first_hits_out != 0ul) {
        HitsOutRef(push.first_hits_out).h[i] = f;
    }
}
