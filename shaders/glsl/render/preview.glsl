// The editor's brush preview: a hit on a voxel inside the tool's region is tinted. The GLSL
// twin of `BrushPreview::contains` / `tint` (engine/render/params.rs); `precise` so the
// inclusion test gives the edit tools' answer bit for bit (shaders/glsl/edit/common.glsl).
#ifndef VOXDAG_RENDER_PREVIEW_GLSL
#define VOXDAG_RENDER_PREVIEW_GLSL

// `preview_shape` values (`params::PREVIEW_*`).
#define PREVIEW_SPHERE 1u
#define PREVIEW_CUBE 2u

// Whether voxel `v` lies in the region (`region`: xyz centre, w radius) of `shape`.
bool preview_contains(vec4 region, uint shape, uvec3 v) {
    if (shape == PREVIEW_CUBE) {
        precise vec3 centre = vec3(v) + 0.5;
        precise vec3 lo = region.xyz - region.w;
        precise vec3 hi = region.xyz + region.w;
        return all(lessThanEqual(lo, centre)) && all(lessThanEqual(centre, hi));
    }
    if (shape == PREVIEW_SPHERE) {
        precise vec3 d = (vec3(v) + 0.5) - region.xyz;
        precise float d2 = d.x * d.x + d.y * d.y + d.z * d.z;
        precise float r2 = region.w * region.w;
        return d2 <= r2;
    }
    return false;
}

// The linear colour `c` of a hit on voxel `v`, tinted when it lies in the region.
vec3 preview_tint(vec3 c, uvec3 v, vec4 region, vec4 color, uint shape) {
    if (!preview_contains(region, shape, v)) {
        return c;
    }
    precise vec3 t = c + (color.rgb - c) * color.w;
    return t;
}

#endif
