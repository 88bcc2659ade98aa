// Frame constants of the renderer. The members come from `RenderParams` in
// engine/render/gpu_shared.rs (generated into gen/render.glsl by build.rs): one definition.
#ifndef VOXDAG_SHARED_RENDER_PARAMS_H
#define VOXDAG_SHARED_RENDER_PARAMS_H

#include "gen/render.glsl"

// `flags` bits.
#define RENDER_FLAG_HAS_COLORS 1u
#define RENDER_FLAG_SHADOWS 2u

struct RenderParams {
    RENDER_PARAMS_MEMBERS
};

#endif
