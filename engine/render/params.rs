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
use crate::edit::tool::{in_cube, in_sphere, Shape};

/// `preview_shape`: no brush preview.
pub const PREVIEW_NONE: u32 = 0;
/// `preview_shape`: a ball (`edit::tool::in_sphere`).
pub const PREVIEW_SPHERE: u32 = 1;
/// `preview_shape`: an axis-aligned cube (`edit::tool::in_cube`).
pub const PREVIEW_CUBE: u32 = 2;

/// The editor's brush preview: voxels seen by the primary ray that lie inside the tool's region
/// (the edit tools' own inclusion rule) are tinted towards `color`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrushPreview {
    /// Ball or cube.
    pub shape: Shape,
    /// Centre (voxel coordinates, as the tool gets it).
    pub center: [f32; 3],
    /// Radius (voxels).
    pub radius: f32,
    /// Linear RGB tint.
    pub color: [f32; 3],
    /// Fraction of the shaded colour the tint replaces (0..=1).
    pub strength: f32,
}

impl BrushPreview {
    /// Whether voxel `v` (integer corner) lies in the region.
    pub fn contains(&self, v: [u32; 3]) -> bool {
        match self.shape {
            Shape::Sphere => in_sphere(self.center, self.radius, v),
            Shape::Cube => in_cube(self.center, self.radius, v),
        }
    }

    /// The tinted linear colour (`preview_tint` in `render/preview.glsl`: same operations).
    pub fn tint(&self, c: [f32; 3]) -> [f32; 3] {
        [0, 1, 2].map(|k| c[k] + (self.color[k] - c[k]) * self.strength)
    }
}

/// `(preview, preview_color, preview_shape)` of the params for `preview`.
pub fn preview_fields(preview: Option<&BrushPreview>) -> ([f32; 4], [f32; 4], u32) {
    match preview {
        None => ([0.0; 4], [0.0; 4], PREVIEW_NONE),
        Some(b) => {
            let c = b.center;
            let shape = match b.shape {
                Shape::Sphere => PREVIEW_SPHERE,
                Shape::Cube => PREVIEW_CUBE,
            };
            (
                [c[0], c[1], c[2], b.radius],
                [b.color[0], b.color[1], b.color[2], b.strength],
                shape,
            )
        }
    }
}

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
        let (preview, preview_color, preview_shape) = preview_fields(settings.preview.as_ref());
        Ok(RenderParams {
            eye: v4(cam.eye, tan),
            right: v4(b.right, pixel_scale(tan, settings.height)),
            up: v4(b.up, dag.resolution as f32 * SHADOW_EPSILON_PER_VOXEL_SIDE),
            forward: v4(b.forward, 0.0),
            light_dir: v4(light, 0.0),
            preview,
            preview_color,
            width: settings.width,
            height: settings.height,
            resolution: dag.resolution,
            root_level: dag.root_level(),
            flags,
            preview_shape,
            color_count,
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

    /// The brush preview tint of a hit on voxel `v`, if it lies in the preview region.
    pub fn preview_tint(&self, v: [u32; 3], c: [f32; 3]) -> [f32; 3] {
        let shape = match self.preview_shape {
            PREVIEW_SPHERE => Shape::Sphere,
            PREVIEW_CUBE => Shape::Cube,
            _ => return c,
        };
        let [x, y, z, radius] = self.preview;
        let [r, g, b, strength] = self.preview_color;
        let preview = BrushPreview {
            shape,
            center: [x, y, z],
            radius,
            color: [r, g, b],
            strength,
        };
        if preview.contains(v) {
            preview.tint(c)
        } else {
            c
        }
    }

    /// True when shadow rays are cast.
    pub fn shadows(&self) -> bool {
        self.flags & FLAG_SHADOWS != 0
    }
}
