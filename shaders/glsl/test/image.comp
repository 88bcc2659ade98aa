#version 460
// Test shader of the GPU layer: writes a gradient into an RGBA8 storage image.
// Pixel (x, y) = (x & 255, y & 255, (x + y + push.seed) & 255, 255) as unorm.
layout(local_size_x = 8, local_size_y = 8) in;

layout(set = 0, binding = 0, rgba8) uniform writeonly image2D img;

#include "gen/test.glsl"
layout(push_constant, std430) uniform Push { IMAGE_PUSH_MEMBERS } push;

void main() {
    uvec2 p = gl_GlobalInvocationID.xy;
    if (p.x >= push.width || p.y >= push.height) {
        return;
    }
    uvec4 v = uvec4(p.x & 255u, p.y & 255u, (p.x + p.y + push.seed) & 255u, 255u);
    imageStore(img, ivec2(p), vec4(v) / 255.0);
}
