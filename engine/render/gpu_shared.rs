// The structs the renderer shares with its shaders, defined once (see engine/gpu_shared.rs):
// the engine expands this file into Rust structs, build.rs into `gen/render.glsl`.
gpu_shared! {
    /// Frame constants shared by the CPU reference renderer and the GPU (`struct RenderParams`
    /// in `render_params.h`): seven `vec4`s, six `uint`s, a `uint64_t`: 144 bytes.
    #[derive(PartialEq)]
    pub struct RenderParams {
        /// xyz: eye position (grid coordinates); w: `tan(fov_y / 2)`.
        pub eye: vec4,
        /// xyz: unit camera right; w: pixel scale `2 tan(fov_y / 2) / height`.
        pub right: vec4,
        /// xyz: unit camera up; w: shadow-ray offset along the normal (grid units).
        pub up: vec4,
        /// xyz: unit viewing direction; w: 0 (reserved).
        pub forward: vec4,
        /// xyz: unit direction towards the light; w: 0 (reserved).
        pub light_dir: vec4,
        /// Brush preview (the editor): xyz centre, w radius (voxels; `params::BrushPreview`).
        pub preview: vec4,
        /// Brush preview: rgb linear tint colour, w how much of it replaces the shaded colour.
        pub preview_color: vec4,
        /// Image width in pixels.
        pub width: uint,
        /// Image height in pixels.
        pub height: uint,
        /// Grid side length N.
        pub resolution: uint,
        /// Level of the DAG root (`log2(N) - 2`).
        pub root_level: uint,
        /// `FLAG_HAS_COLORS | FLAG_SHADOWS`.
        pub flags: uint,
        /// Brush preview shape: 0 none, 1 sphere, 2 cube (`params::PREVIEW_*`).
        pub preview_shape: uint,
        /// Colours stored (0 without colours; 64-bit: huge scenes exceed 2^32 voxels); larger
        /// colour indices shade white.
        pub color_count: uint64_t,
    }

    /// Push constants of `primary.comp`: device addresses of its buffers, then the colour format.
    pub(crate) struct PrimaryPush {
        /// `RenderParams`.
        pub(crate) params: uint64_t,
        /// The DAG's words.
        pub(crate) words: uint64_t,
        /// Voxel count below each node (`u64` per DAG word, colour indexing).
        pub(crate) node_voxels: uint64_t,
        /// Encoded colour words.
        pub(crate) color_words: uint64_t,
        /// First voxel of each colour chunk.
        pub(crate) chunk_starts: uint64_t,
        /// Word offset of each colour chunk.
        pub(crate) chunk_offsets: uint64_t,
        /// One hit flag per pixel, or 0: no hit mask (the viewer).
        pub(crate) hits: uint64_t,
        /// One `FirstHit` per pixel, or 0: none written.
        pub(crate) first_hits: uint64_t,
        /// `ColorFormat` id.
        pub(crate) color_format: uint,
        /// Number of colour chunks.
        pub(crate) chunk_count: uint,
        /// The root to traverse for formats whose root changes per frame (hash DAG: the root's
        /// child value, `render/dag_hash.glsl`); 0 otherwise.
        pub(crate) dag_root: uint,
        /// Explicit padding to 8 bytes.
        pub(crate) _pad: uint,
    }

    /// The primary ray's first hit of one pixel (`GpuRenderer::render_first_hits`): what every
    /// DAG format must reproduce exactly. 40 bytes.
    #[derive(PartialEq, Eq, Default)]
    pub struct FirstHit {
        /// 1 when the ray hit a voxel (then the other fields are set), else 0 and all zero.
        pub hit: uint,
        /// Bits of the entry parameter `t` (f32).
        pub t_bits: uint,
        /// The voxel hit (x, y, z).
        pub voxel: [uint; 3],
        /// Entry face normal (x, y, z), pointing against the ray.
        pub normal: [int; 3],
        /// Depth-first Morton index of the voxel (index into the colours); hash DAG: the voxel's
        /// material (index into the palette).
        pub color_index: uint64_t,
    }

    /// Push constants of `render/accum_display.comp` (`render::pt_view`): the path tracer's
    /// accumulation and first hits, the image's first hits, size, samples and brush preview.
    pub(crate) struct PtDisplayPush {
        /// `vec4` per pixel: summed radiance and sample count (`PtParams::accum`).
        pub(crate) accum: uint64_t,
        /// `FirstHit` per pixel of the accumulation (`PtParams::first_hits`).
        pub(crate) first_hits: uint64_t,
        /// Host-visible `FirstHit` per pixel the pass copies them to, or 0.
        pub(crate) first_hits_out: uint64_t,
        /// Image width in pixels.
        pub(crate) width: uint,
        /// Image height in pixels.
        pub(crate) height: uint,
        /// `RenderParams::preview`.
        pub(crate) preview: vec4,
        /// `RenderParams::preview_color`.
        pub(crate) preview_color: vec4,
        /// `RenderParams::preview_shape`.
        pub(crate) preview_shape: uint,
        /// Samples accumulated (the divisor).
        pub(crate) spp: uint,
        /// Explicit padding to 16 bytes.
        pub(crate) _pad: [uint; 2],
    }

    /// Path-tracing constants of one render (`struct PtParams` in `render/pt_common.glsl`),
    /// next to a `RenderParams` for the camera: environment, sun, limits and the device
    /// addresses of the accumulation, first-hit and wavefront buffers (0 where unused).
    pub struct PtParams {
        /// rgb: constant environment radiance; w: uniform albedo, or -1: voxel colours.
        pub env: vec4,
        /// xyz: unit direction towards the sun; w: its intensity (0: no sun).
        pub sun: vec4,
        /// `vec4` per pixel: summed radiance (rgb) and sample count (w).
        pub accum: uint64_t,
        /// `FirstHit` per pixel, written by sample 0 (0: none).
        pub first_hits: uint64_t,
        /// 256 `float`s: sRGB byte -> linear (`pathtrace::srgb_lut`).
        pub srgb_lut: uint64_t,
        /// Wavefront: one `PtPath` per pixel.
        pub paths: uint64_t,
        /// Wavefront: extension queue read by even bounces.
        pub queue_a: uint64_t,
        /// Wavefront: extension queue read by odd bounces.
        pub queue_b: uint64_t,
        /// Wavefront: survival flag per queue slot (compaction input).
        pub flags: uint64_t,
        /// Wavefront: `[count, x, y, z]` of the extension queue.
        pub ext_count: uint64_t,
        /// Wavefront: the shadow-ray queue.
        pub shadow_queue: uint64_t,
        /// Wavefront: `[count, x, y, z]` of the shadow queue.
        pub shadow_count: uint64_t,
        /// Surface interactions a path may have before it must escape (`--bounces`).
        pub bounces: uint,
        /// Seed of the counter-based RNG.
        pub seed: uint,
        /// First interaction that plays Russian roulette.
        pub rr_depth: uint,
        /// Width x height.
        pub pixels: uint,
    }

    /// Push constants of every path-tracing shader (`pt_mega.comp`, `pt_*.comp`): device
    /// addresses of the constants and the scene, the colour format, then the sample and bounce.
    pub(crate) struct PtPush {
        /// `RenderParams` (camera, resolution, colour flags; `up.w` = ray offset).
        pub(crate) params: uint64_t,
        /// `PtParams`.
        pub(crate) pt: uint64_t,
        /// The DAG's words.
        pub(crate) words: uint64_t,
        /// Voxel count below each node (`u64` per DAG word, colour indexing).
        pub(crate) node_voxels: uint64_t,
        /// Encoded colour words.
        pub(crate) color_words: uint64_t,
        /// First voxel of each colour chunk.
        pub(crate) chunk_starts: uint64_t,
        /// Word offset of each colour chunk.
        pub(crate) chunk_offsets: uint64_t,
        /// `ColorFormat` id.
        pub(crate) color_format: uint,
        /// Number of colour chunks.
        pub(crate) chunk_count: uint,
        /// Index of the sample being traced (RNG key; 0 writes the first hits).
        pub(crate) sample_index: uint,
        /// Wavefront: the bounce of this pass (0 = camera rays).
        pub(crate) bounce: uint,
        /// The root to traverse for formats whose root changes per frame (hash DAG: the root's
        /// child value, `render/dag_hash.glsl`); 0 otherwise.
        pub(crate) dag_root: uint,
        /// Explicit padding to 8 bytes.
        pub(crate) _pad: uint,
    }
}
