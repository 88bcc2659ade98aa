// The sRGB transfer curve (`crate::color`): shared by shade.glsl and accum_display.comp.
#ifndef VOXDAG_RENDER_SRGB_GLSL
#define VOXDAG_RENDER_SRGB_GLSL

float shade_srgb_to_linear(float c) {
    return c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4);
}

float shade_linear_to_srgb(float l) {
    l = clamp(l, 0.0, 1.0);
    return l <= 0.0031308 ? l * 12.92 : 1.055 * pow(l, 1.0 / 2.4) - 0.055;
}

vec4 shade_encode(vec3 linear_rgb) {
    return vec4(shade_linear_to_srgb(linear_rgb.r), shade_linear_to_srgb(linear_rgb.g),
                shade_linear_to_srgb(linear_rgb.b), 1.0);
}

#endif
