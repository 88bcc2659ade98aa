//! Out-of-core path tracing of triangle scenes larger than memory (dissertation ch. 6).
//!
//! CPU-only. A scene directory (written by [`prepare::prepare`]) holds the triangles grouped
//! into spatially compact *batching points*, each in its own checksummed region of
//! `geometry.bin`, an index with the points' bounds, and per proxy resolution one shared
//! multi-root SVDAG of conservative voxelizations (`proxies-R.bin`). [`render`] traces paths
//! with batched ray traversal (Pharr et al. 1997): rays wait in per-point queues, the point with
//! the most queued rays is loaded (LRU cache under a memory budget) and all its rays are
//! intersected at once. With proxies on, a ray is queued at a point only when it touches the
//! point's SVDAG proxy, which skips loads of geometry the ray would miss. See
//! `docs/out-of-core.md`.

pub mod format;
pub mod geom;
pub mod prepare;
pub mod proxy;
pub mod render;

use std::path::{Path, PathBuf};

pub use format::{OocScene, PointEntry};
pub use prepare::{prepare, PrepareOptions, PrepareSummary, SceneSource, Terrain};
pub use proxy::{Grid, ProxySet};
pub use render::{render_in_core, render_out_of_core, Image, RenderOptions, RenderStats};

/// Errors of scene preparation, scene loading and rendering; each names the file involved.
#[derive(Debug, thiserror::Error)]
pub enum OocError {
    /// A scene file is malformed: `offset` is the byte offset of the offending field.
    #[error("{}: byte offset {offset}: {reason}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// Byte offset in the file.
        offset: u64,
        /// What is wrong.
        reason: String,
    },
    /// An I/O error on a file.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// Importing an input mesh failed.
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    /// Building a proxy SVDAG failed.
    #[error(transparent)]
    Dag(#[from] crate::dag::DagError),
    /// An allocation sized by the input would pass the memory limit.
    #[error(transparent)]
    Memory(#[from] crate::safety::MemoryError),
    /// An option is unusable (budget too small, bad resolution, ...).
    #[error("{0}")]
    Invalid(String),
}

impl OocError {
    /// An I/O error on `path`.
    pub fn io(path: &Path, source: std::io::Error) -> OocError {
        OocError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
