//! Rendering: camera, GPU SVDAG traversal and its CPU reference.
//!
//! The CPU renderer ([`cpu::render_cpu`]) and the GPU renderer build their rays from the same
//! [`params::RenderParams`] and run the same traversal and shading (`shaders/glsl/render/`),
//! so their hit masks agree exactly up to edge cases (see `docs/rendering.md`).

pub mod camera;
pub mod cpu;
pub mod format;
pub mod gpu;
mod gpu_shared;
pub mod hash_scene;
pub mod params;
pub mod pathtrace;
pub mod pathtrace_gpu;
pub mod pt_view;

use std::io;
use std::path::{Path, PathBuf};

pub use camera::Camera;
pub use cpu::render_cpu;
pub use format::TraversalFormat;
pub use gpu_shared::FirstHit;
pub use params::RenderParams;

/// What a render needs besides the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// The camera (grid coordinates).
    pub camera: Camera,
    /// Direction towards the directional light (normalised by `RenderParams::new`).
    pub light_dir: [f32; 3],
    /// Cast one shadow ray per hit.
    pub shadows: bool,
    /// The editor's brush preview (tinted voxels); `None` everywhere else.
    pub preview: Option<params::BrushPreview>,
}

impl RenderSettings {
    /// Settings with the default light (`params::DEFAULT_LIGHT_DIR`) and shadows on.
    pub fn new(width: u32, height: u32, camera: Camera) -> RenderSettings {
        RenderSettings {
            width,
            height,
            camera,
            light_dir: params::DEFAULT_LIGHT_DIR,
            shadows: true,
            preview: None,
        }
    }
}

/// A rendered image and its per-pixel hit mask.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RenderOutput {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// sRGB RGBA8 pixels, row-major from the top-left corner.
    pub rgba: Vec<u8>,
    /// One entry per pixel: 1 when the primary ray hit a voxel, 0 otherwise.
    pub hits: Vec<u32>,
}

/// Errors of the render module.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// Width or height is zero.
    #[error("image size {width}x{height} is empty")]
    EmptyImage {
        /// Requested width.
        width: u32,
        /// Requested height.
        height: u32,
    },
    /// The grid resolution is not a power of two in `8..=MAX_GPU_RESOLUTION`.
    #[error("resolution {0} unsupported: need a power of two in 8..=2097152")]
    Resolution(u32),
    /// The light direction is zero or not finite.
    #[error("light direction {0:?} is zero or not finite")]
    LightDir([f32; 3]),
    /// The `VoxelIndex` was not built for this DAG.
    #[error("voxel index has {index} entries but the DAG has {words} words")]
    IndexMismatch {
        /// Entries of `VoxelIndex::node_voxels`.
        index: usize,
        /// Words of the DAG.
        words: usize,
    },
    /// `rgba` or `hits` does not match `width x height`.
    #[error("render output buffers do not match {width}x{height}")]
    BufferSize {
        /// Image width.
        width: u32,
        /// Image height.
        height: u32,
    },
    /// Writing the image failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// File being written.
        path: PathBuf,
        /// Underlying error.
        source: std::io::Error,
    },
}

impl RenderOutput {
    /// Number of pixels whose primary ray hit a voxel.
    pub fn hit_count(&self) -> usize {
        self.hits.iter().filter(|&&h| h != 0).count()
    }

    /// Writes the image as an RGBA8 PNG, atomically (temporary file in the same folder, fsync,
    /// rename).
    pub fn save_png(&self, path: &Path) -> Result<(), RenderError> {
        let pixels = self.width as usize * self.height as usize;
        if self.rgba.len() != pixels * 4 || self.width == 0 || self.height == 0 {
            return Err(RenderError::BufferSize {
                width: self.width,
                height: self.height,
            });
        }
        let encoded = crate::atomic_file::write_atomic(path, |writer| {
            image::ImageEncoder::write_image(
                image::codecs::png::PngEncoder::new(writer),
                &self.rgba,
                self.width,
                self.height,
                image::ExtendedColorType::Rgba8,
            )
            .map_err(io::Error::other)
        });
        encoded.map_err(|source| RenderError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}
