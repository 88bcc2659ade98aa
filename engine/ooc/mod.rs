//! Out-of-core path tracing of triangle scenes larger than memory (dissertation ch. 6).
//!
//! CPU-only. A scene directory (written by [`prepare::prepare`]) holds the triangles grouped
//! into spatially compact *batching points*, each in its own checksummed region of
//! `geometry.bin`, an index with the points' bounds, and per proxy resolution one shared
//! multi-root SVDAG of conservative voxelizations (`proxies-R.bin`). [`render`] traces paths
//! with batched ray traversal (Pharr et al. 1997): rays wait in per-point queues, the point with
//! the most queued rays is loaded (a cache under a memory budget, evicting the point the fewest
//! queued rays still need) and all its rays are
//! intersected at once. With proxies on, a ray is queued at a point only when it touches the
//! point's SVDAG proxy, which skips loads of geometry the ray would miss. See
//! `docs/out-of-core.md`.

pub mod forest;
pub mod format;
pub mod geom;
pub mod prepare;
pub mod proxy;
pub mod render;

use std::path::Path;

use crate::dag::DagError;

pub use format::{OocScene, PointEntry};
pub use prepare::{prepare, GeneratedScene, PrepareOptions, PrepareSummary, SceneSource, Terrain};
pub use proxy::{Grid, ProxySet};
pub use render::{
    render_in_core, render_out_of_core, Eviction, Image, RenderOptions, RenderStats, Resident,
    Schedule,
};

/// Errors of scene preparation, scene loading and rendering; each names the file involved.
/// Malformed files and I/O errors are [`DagError::Format`] and [`DagError::Io`] (the same
/// variants the SVDAG files use), wrapped in [`OocError::Dag`].
#[derive(Debug, thiserror::Error)]
pub enum OocError {
    /// Importing an input mesh failed.
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    /// A scene file is malformed or unreadable ([`DagError::Format`], [`DagError::Io`]), or
    /// building a proxy SVDAG failed.
    #[error(transparent)]
    Dag(#[from] DagError),
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
        OocError::Dag(DagError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    /// A malformed file: `offset` is the byte offset of the offending field.
    pub fn format(path: &Path, offset: u64, reason: String) -> OocError {
        OocError::Dag(DagError::Format {
            path: path.to_path_buf(),
            offset,
            reason,
        })
    }
}
