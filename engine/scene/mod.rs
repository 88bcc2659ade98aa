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
/// Files the model references must lie in its own folder (see [`import_in`]).
pub fn import(
    path: &Path,
    opts: &ImportOptions,
    progress: &ProgressBar,
) -> Result<Voxels, SceneError> {
    import_in(path, opts, None, progress)
}

/// [`import`] with the asset root widened to `asset_root` (`--asset-root`): a file the model
/// references (glTF buffers and images, OBJ material libraries and textures) is opened only
/// when its lexically normalized path lies under the model's folder or `asset_root`.
pub fn import_in(
    path: &Path,
    opts: &ImportOptions,
    asset_root: Option<&Path>,
    progress: &ProgressBar,
) -> Result<Voxels, SceneError> {
    match open_in(path, opts, asset_root)? {
        Source::Voxels(voxels) => Ok(voxels),
        Source::Mesh { mesh, resolution } => voxelize(&mesh, resolution, progress),
    }
}

/// A scene file opened for voxelization: what [`open_in`] yields.
#[derive(Clone, Debug)]
pub enum Source {
    /// A .vox model, already voxels (bounded by its own import guard).
    Voxels(Voxels),
    /// A mesh, loaded with every input-sized allocation checked against the memory limit, and
    /// the validated resolution to voxelize it at.
    Mesh {
        /// The mesh in model space.
        mesh: Mesh,
        /// Grid resolution (`opts.resolution`, default 1024).
        resolution: u32,
    },
}

/// Opens a scene file for [`import_in`] or a streaming voxelization
/// ([`voxelize::voxelize_stream`]): the one import path of both, with the same checks
/// (extension, resolution, asset roots, the memory limit on every input-sized allocation).
pub fn open_in(
    path: &Path,
    opts: &ImportOptions,
    asset_root: Option<&Path>,
) -> Result<Source, SceneError> {
    match extension(path).as_str() {
        "vox" => Ok(Source::Voxels(load_vox(path, opts)?)),
        "obj" | "gltf" | "glb" => {
            let resolution = opts.resolution.unwrap_or(DEFAULT_MESH_RESOLUTION);
            voxelize::check_resolution(resolution, path)?;
            let mesh = load_mesh_in(path, opts, asset_root)?;
            Ok(Source::Mesh { mesh, resolution })
        }
        ext => Err(SceneError::Unsupported {
            path: path.to_path_buf(),
            extension: ext.to_string(),
        }),
    }
}

/// Loads a triangle mesh (.obj with .mtl, .gltf, .glb) in model space.
pub fn load_mesh(path: &Path, opts: &ImportOptions) -> Result<Mesh, SceneError> {
    load_mesh_in(path, opts, None)
}

/// [`load_mesh`] with the asset root widened to `asset_root` (see [`import_in`]).
pub fn load_mesh_in(
    path: &Path,
    opts: &ImportOptions,
    asset_root: Option<&Path>,
) -> Result<Mesh, SceneError> {
    let roots = AssetRoots::new(path, asset_root);
    let mesh = match extension(path).as_str() {
        "obj" => obj::load_obj(path, opts, &roots)?,
        "gltf" | "glb" => gltf_load::load_gltf(path, &roots)?,
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
    match crate::safety::catch_quietly(f) {
        Ok(r) => r,
        Err(message) => Err(SceneError::Parse {
            path: path.to_path_buf(),
            format,
            message,
        }),
    }
}

/// Loads an image file as an RGBA8 texture.
fn load_texture(path: &Path) -> Result<Texture, String> {
    texture_from_bytes(&read_bounded(path, "texture")?)
}

/// Reads a whole regular file after checking its size against the memory limit.
fn read_bounded(path: &Path, what: &str) -> Result<Vec<u8>, String> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let meta = file.metadata().map_err(|e| e.to_string())?;
    if !meta.is_file() {
        return Err(format!("{} is not a regular file", path.display()));
    }
    crate::safety::check_memory(format!("{what} {}", path.display()), meta.len())
        .map_err(|e| e.to_string())?;
    let mut bytes = Vec::new();
    bytes
        .try_reserve_exact(meta.len() as usize)
        .map_err(|e| e.to_string())?;
    file.take(meta.len())
        .read_to_end(&mut bytes)
        .map_err(|e| e.to_string())?;
    Ok(bytes)
}

/// Decodes an encoded image (PNG, JPEG) as an RGBA8 texture, its decoded size bounded by the
/// memory limit.
fn texture_from_bytes(bytes: &[u8]) -> Result<Texture, String> {
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| e.to_string())?;
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(crate::safety::memory_limit());
    reader.limits(limits);
    let img = reader.decode().map_err(|e| e.to_string())?;
    let (w, h) = (img.width() as u64, img.height() as u64);
    crate::safety::check_memory("texture", w * h * 8).map_err(|e| e.to_string())?;
    let rgba = img.to_rgba8();
    let (w, h) = rgba.dimensions();
    let texels = rgba.pixels().map(|p| p.0).collect();
    Texture::new(w, h, texels).ok_or_else(|| "empty image".to_string())
}

/// The folders a model may reference files in: its own folder and `--asset-root`, both
/// absolute and lexically normalized.
#[derive(Clone, Debug)]
pub(crate) struct AssetRoots {
    /// The model's folder (relative references resolve against it).
    pub(crate) base: PathBuf,
    /// Every allowed root (the base first).
    roots: Vec<PathBuf>,
}

/// `path` made absolute (against the current folder) and lexically normalized: `.` dropped,
/// `..` removes the previous component (never above `/`). Symlinks are not resolved.
pub(crate) fn normalize(path: &Path) -> PathBuf {
    use std::path::Component;
    let absolute = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .unwrap_or_else(|_| PathBuf::from("/"))
            .join(path)
    };
    let mut out = PathBuf::new();
    for c in absolute.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

impl AssetRoots {
    /// The roots of the model at `model`, widened by `extra`.
    pub(crate) fn new(model: &Path, extra: Option<&Path>) -> AssetRoots {
        let base = normalize(model.parent().unwrap_or(Path::new(".")));
        let mut roots = vec![base.clone()];
        roots.extend(extra.map(normalize));
        AssetRoots { base, roots }
    }

    /// Resolves a reference (already percent-decoded for URIs) to a path under a root that
    /// names a regular file (symlinks followed); otherwise says why it is refused.
    pub(crate) fn resolve(&self, reference: &str) -> Result<PathBuf, String> {
        let rule = "referenced files must lie in the model's folder or under --asset-root";
        if reference.is_empty() {
            return Err("an empty file reference".into());
        }
        let raw = Path::new(reference);
        if raw.is_absolute() {
            return Err(format!("{reference:?} is an absolute path ({rule})"));
        }
        let path = normalize(&self.base.join(raw));
        if !self.roots.iter().any(|r| path.starts_with(r)) {
            return Err(format!(
                "{reference:?} resolves to {}, outside the asset root {} ({rule})",
                path.display(),
                self.roots
                    .iter()
                    .map(|r| r.display().to_string())
                    .collect::<Vec<_>>()
                    .join(" and ")
            ));
        }
        match std::fs::metadata(&path) {
            Ok(m) if m.is_file() => Ok(path),
            Ok(_) => Err(format!("{} is not a regular file", path.display())),
            Err(e) => Err(format!("{}: {e}", path.display())),
        }
    }

    /// [`AssetRoots::resolve`] then [`read_bounded`].
    pub(crate) fn read(&self, reference: &str, what: &str) -> Result<Vec<u8>, String> {
        read_bounded(&self.resolve(reference)?, what)
    }
}

/// Decodes `%XX` escapes of a URI path (RFC 3986); the result must be UTF-8.
pub(crate) fn percent_decode(uri: &str) -> Result<String, String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = b
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| format!("bad percent escape in URI {uri:?}"))?;
            out.push(hex);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).map_err(|_| format!("URI {uri:?} is not UTF-8 once decoded"))
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
