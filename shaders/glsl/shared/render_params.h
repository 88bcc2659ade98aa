// Frame constants of the renderer: mirror of `RenderParams` in engine/render/params.rs.
// std430 / scalar layout, 112 bytes: five vec4s, then eight uints. Keep both in sync (the Rust
// side asserts every offset listed here).
#ifndef VOXDAG_SHARED_RENDER_PARAMS_H
#define VOXDAG_SHARED_RENDER_PARAMS_H

// `flags` bits.
#define RENDER_FLAG_HAS_COLORS 1u
#define RENDER_FLAG_SHADOWS 2u

struct RenderParams {
    vec4 eye;        // offset 0:  xyz eye (grid coordinates), w tan(fov_y / 2)
    vec4 right;      // offset 16: xyz unit camera right, w pixel scale 2 tan(fov_y / 2) / height
    vec4 up;         // offset 32: xyz unit camera up, w shadow-ray offset along the normal
    vec4 forward;    // offset 48: xyz unit view direction, w 0 (reserved)
    vec4 light_dir;  // offset 64: xyz unit direction towards the light, w 0 (reserved)
    uint width;      // offset 80: image width in pixels
    uint height;     // offset 84: image height in pixels
    uint resolution; // offset 88: grid side N
    uint root_level; // offset 92: log2(N) - 2
    uint flags;      // offset 96: RENDER_FLAG_*
    uint color_count; // offset 100: entries of the colour buffer (0 without colours)
    uint pad0;       // offset 104: explicit padding
    uint pad1;       // offset 108: explicit padding
};

#endif
