//! `RenderParams`: the per-frame constants shared by the CPU reference renderer and the GPU
//! (defined once in `render/gpu_shared.rs`, from which build.rs generates the GLSL members).

use super::camera::{generate_ray, normalize, pixel_scale, CameraBasis};
use super::{RenderError, RenderSettings};
use crate::dag::raycast::Ray;
use crate::dag::Svdag;

/// `flags` bit: the scene has per-voxel colours.
pub const FLAG_HAS_COLORS: u32 = 1;
/// `flags` bit: cast shadow rays.
pub const FLAG_SHADOWS: u32 = 2;
/// Largest grid the renderers support: every valid `.vdag` file ([`crate::dag::MAX_RESOLUTION`],
/// 2^21; its stack has `MAX_GPU_FRAMES` frames).
pub const MAX_GPU_RESOLUTION: u32 = crate::dag::MAX_RESOLUTION;
/// Stack frames of the GLSL traversal (`TRAVERSE_MAX_FRAMES` in `traverse.glsl`): root level
/// `log2(N) - 2` plus the leaf's two sub-levels.
pub const MAX_GPU_FRAMES: u32 = MAX_GPU_RESOLUTION.trailing_zeros();
/// Shadow-ray start offset along the normal, as a fraction of the resolution (2^-18 N: about 32
/// f32 ulps of the largest coordinate, 0.25 voxel at 64K^3, 8 voxels at 2^21, 3e-5 voxel at 8^3).
pub const SHADOW_EPSILON_PER_VOXEL_SIDE: f32 = 1.0 / 262144.0;

pub use super::gpu_shared::RenderParams;

/// Default direction towards the light (normalised when used).
pub const DEFAULT_LIGHT_DIR: [f32; 3] = [0.4, 1.0, 0.3];

impl RenderParams {
    /// Frame constants for `settings` and `dag`. Fails on an empty image, a resolution the GPU
    /// stack cannot hold, more than 2^32 colours (the GPU uses `uint` colour indices) or a zero
    /// light direction.
    pub fn new(settings: &RenderSettings, dag: &Svdag) -> Result<RenderParams, RenderError> {
        Self::with_colors(settings, dag, dag.colors.len() as u64)
    }

    /// [`RenderParams::new`] for a scene with `color_count` colours stored apart from the DAG
    /// (only the resolution of `dag` is read).
    pub fn with_colors(
        settings: &RenderSettings,
        dag: &Svdag,
        color_count: u64,
    ) -> Result<RenderParams, RenderError> {
        if settings.width == 0 || settings.height == 0 {
            return Err(RenderError::EmptyImage {
                width: settings.width,
                height: settings.height,
            });
        }
        if !dag.resolution.is_power_of_two()
            || dag.resolution < 8
            || dag.resolution > MAX_GPU_RESOLUTION
        {
            return Err(RenderError::Resolution(dag.resolution));
        }
        let light =
            normalize(settings.light_dir).ok_or(RenderError::LightDir(settings.light_dir))?;
        let cam = &settings.camera;
        let b = cam.basis();
        let tan = cam.tan_half_fov();
        let v4 = |v: [f32; 3], w: f32| [v[0], v[1], v[2], w];
        let mut flags = 0;
        if color_count > 0 {
            flags |= FLAG_HAS_COLORS;
        }
        if settings.shadows {
            flags |= FLAG_SHADOWS;
        }
        Ok(RenderParams {
            eye: v4(cam.eye, tan),
            right: v4(b.right, pixel_scale(tan, settings.height)),
            up: v4(b.up, dag.resolution as f32 * SHADOW_EPSILON_PER_VOXEL_SIDE),
            forward: v4(b.forward, 0.0),
            light_dir: v4(light, 0.0),
            width: settings.width,
            height: settings.height,
            resolution: dag.resolution,
            root_level: dag.root_level(),
            flags,
            color_count,
            _pad: 0,
        })
    }

    /// Camera frame stored in the params.
    pub fn basis(&self) -> CameraBasis {
        let xyz = |v: [f32; 4]| [v[0], v[1], v[2]];
        CameraBasis {
            right: xyz(self.right),
            up: xyz(self.up),
            forward: xyz(self.forward),
        }
    }

    /// Primary ray through the centre of `pixel`, exactly as `shade.glsl` builds it.
    pub fn primary_ray(&self, pixel: [u32; 2]) -> Ray {
        generate_ray(
            [self.eye[0], self.eye[1], self.eye[2]],
            &self.basis(),
            self.right[3],
            pixel,
            self.width,
            self.height,
        )
    }

    /// True when the scene has colours.
    pub fn has_colors(&self) -> bool {
        self.flags & FLAG_HAS_COLORS != 0
    }

    /// True when shadow rays are cast.
    pub fn shadows(&self) -> bool {
        self.flags & FLAG_SHADOWS != 0
    }
}
