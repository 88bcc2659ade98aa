//! Scene import (OBJ, glTF, MagicaVoxel .vox) and conservative surface voxelization.
//!
//! Everything here is CPU-only. The output of this stage is a [`Voxels`] set in Morton order,
//! which `dag` turns into an SVO/SVDAG.

use std::path::{Path, PathBuf};

use indicatif::ProgressBar;

mod gltf_load;
pub mod mesh;
pub mod morton;
mod obj;
mod vox;
pub mod voxelize;

pub use mesh::{Material, Mesh, Texture, Wrap};
pub use vox::load_vox;
pub use voxelize::{voxelize, voxelize_brute_force};

/// Resolution used for meshes when [`ImportOptions::resolution`] is `None`.
pub const DEFAULT_MESH_RESOLUTION: u32 = 1024;

/// Options for [`import`], [`load_mesh`] and [`load_vox`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImportOptions {
    /// Grid resolution (power of two, 8..=65536); `None`: 1024 for meshes, the smallest
    /// power of two that fits (at least 8) for .vox.
    pub resolution: Option<u32>,
    /// Integer scale factor for .vox models (each voxel becomes `vox_scale^3` voxels); >= 1.
    pub vox_scale: u32,
    /// Base-colour texture applied to every triangle of an OBJ file (for OBJ files without a
    /// .mtl, e.g. `spot`); replaces the OBJ materials.
    pub texture_override: Option<PathBuf>,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            resolution: None,
            vox_scale: 1,
            texture_override: None,
        }
    }
}

/// Errors of scene import and voxelization; every variant names the file involved.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The file extension is not one of obj, gltf, glb, vox.
    #[error("{path}: unsupported file extension {extension:?} (expected obj, gltf, glb or vox)")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// Its extension (empty if none).
        extension: String,
    },
    /// Reading a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file could not be parsed.
    #[error("{path}: invalid {format} file: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// "obj", "gltf" or "vox".
        format: &'static str,
        /// The parser's message.
        message: String,
    },
    /// The requested resolution is not a power of two in 8..=65536.
    #[error("{path}: bad resolution {resolution}: {reason}")]
    BadResolution {
        /// The file.
        path: PathBuf,
        /// The requested resolution.
        resolution: u32,
        /// Why it was rejected.
        reason: String,
    },
    /// The scene does not fit the requested grid or the available memory.
    #[error("{path}: too large: {reason}")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// The mesh is unusable (no triangles, indices out of range, zero extent, ...).
    #[error("{path}: invalid mesh: {reason}")]
    InvalidMesh {
        /// The file the mesh came from (empty for meshes built in code).
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// An option is invalid (e.g. `vox_scale` 0).
    #[error("{path}: invalid option: {reason}")]
    BadOption {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Lower-case extension of `path` (empty if none).
fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// Imports a scene file into voxels: meshes (.obj, .gltf, .glb) are voxelized at
/// `opts.resolution` (default 1024); .vox files are loaded natively (see [`load_vox`]).
pub fn import(
    path: &Path,
    opts: &ImportOptions,
    progress: &ProgressBar,
) -> Result<Voxels, SceneError> {
    match extension(path).as_str() {
        "vox" => load_vox(path, opts),
        "obj" | "gltf" | "glb" => {
            let resolution = opts.resolution.unwrap_or(DEFAULT_MESH_RESOLUTION);
            voxelize::check_resolution(resolution, path)?;
            let mesh = load_mesh(path, opts)?;
            voxelize(&mesh, resolution, progress)
        }
        ext => Err(SceneError::Unsupported {
            path: path.to_path_buf(),
            extension: ext.to_string(),
        }),
    }
}

/// Loads a triangle mesh (.obj with .mtl, .gltf, .glb) in model space.
pub fn load_mesh(path: &Path, opts: &ImportOptions) -> Result<Mesh, SceneError> {
    let mesh = match extension(path).as_str() {
        "obj" => obj::load_obj(path, opts)?,
        "gltf" | "glb" => gltf_load::load_gltf(path)?,
        ext => {
            return Err(SceneError::Unsupported {
                path: path.to_path_buf(),
                extension: ext.to_string(),
            })
        }
    };
    mesh.validate()?;
    Ok(mesh)
}

/// Runs a third-party parser, turning a panic inside it into a parse error.
fn guard<T>(
    path: &Path,
    format: &'static str,
    f: impl FnOnce() -> Result<T, SceneError>,
) -> Result<T, SceneError> {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(e) => {
            let msg = e
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| e.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "parser panicked".to_string());
            Err(SceneError::Parse {
                path: path.to_path_buf(),
                format,
                message: msg,
            })
        }
    }
}

/// Loads an image file as an RGBA8 texture.
fn load_texture(path: &Path) -> Result<Texture, String> {
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    let img = image::load_from_memory(&bytes).map_err(|e| e.to_string())?;
    let rgba = img.to_rgba8();
    let (w, h) = rgba.dimensions();
    let texels = rgba.pixels().map(|p| p.0).collect();
    Texture::new(w, h, texels).ok_or_else(|| "empty image".to_string())
}

/// A set of occupied voxels in a cubic grid, sorted by Morton code, with optional colours.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Voxels {
    /// Grid side length N (a power of two); every coordinate is in `0..N`.
    pub resolution: u32,
    /// Morton codes of the occupied voxels, strictly ascending (no duplicates).
    pub codes: Vec<u64>,
    /// One RGBA8 colour per voxel (`r | g << 8 | b << 16 | a << 24`, sRGB), in the order of
    /// `codes`; empty when the scene has no colours.
    pub colors: Vec<u32>,
}

impl Voxels {
    /// An uncoloured voxel set from coordinates (any order, duplicates allowed; each below `resolution`).
    pub fn from_coords(resolution: u32, coords: impl IntoIterator<Item = [u32; 3]>) -> Voxels {
        let mut codes: Vec<u64> = coords
            .into_iter()
            .map(|[x, y, z]| morton::encode(x, y, z))
            .collect();
        codes.sort_unstable();
        codes.dedup();
        Voxels {
            resolution,
            codes,
            colors: Vec::new(),
        }
    }

    /// Number of occupied voxels.
    pub fn len(&self) -> usize {
        self.codes.len()
    }

    /// True when no voxel is occupied.
    pub fn is_empty(&self) -> bool {
        self.codes.is_empty()
    }

    /// True when every voxel carries a colour.
    pub fn has_colors(&self) -> bool {
        !self.colors.is_empty()
    }
}
