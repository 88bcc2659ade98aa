//! Compact encodings of (transform-aware) SVDAGs and traversal of the encoded bytes themselves
//! (dissertation §3.4; byte layouts in `docs/encodings.md`).
//!
//! - `svdag32`: [`crate::dag::Svdag`] words unchanged (32-bit masks and pointers), the baseline.
//! - `ssvdag`: [`SsvdagEncoding`], the SSVDAG of Villanueva et al. 2016 (3 mirror bits per
//!   pointer, published 3-bit invariance) with 16/32-bit variable-length pointers.
//! - `tsvdag`: [`TsvdagEncoding`], the transform-aware SVDAG: 16-bit node headers with 2 bits per
//!   child, 16/32/48-bit pointers, per-level 64-bit pointer look-up tables chosen greedily,
//!   length-limited Huffman-coded transform ids and translation amounts, nodes sorted by
//!   reference count. Every feature is switchable at run time ([`TsvdagOptions`]).
//!
//! Every encoding implements [`TreeView`], the traversal of the encoded bytes (no decoding to an
//! SVO): point lookup ([`contains`]), voxel enumeration in Morton order ([`VoxelIter`]), ray
//! cast ([`raycast`]) and conversion back to an SVDAG ([`to_svdag`]).

mod bytes;
mod huffman;
mod ssvdag;
mod traverse;
mod tsvdag;

pub use huffman::{length_limited_code_lengths, Huffman};
pub use ssvdag::SsvdagEncoding;
pub use traverse::{
    contains, occupied_bounds, raycast, to_svdag, voxel_digest, Bounds, EncodedHit, TreeView,
    VoxelIter,
};
pub use tsvdag::{
    reorient, GraphLevel, GraphPointer, TransformGraph, TranslationCoding, TsvdagEncoding,
    TsvdagOptions, TsvdagTuning, MAX_TRANSLATION_LEVEL,
};

/// Errors of encoding and of decoding encoded bytes.
#[derive(Debug, thiserror::Error)]
pub enum EncodeError {
    /// The DAG does not fit the pointer sizes of the encoding.
    #[error("cannot encode: {0}")]
    TooLarge(String),
    /// The input graph breaks its invariants (e.g. a translation where none is allowed).
    #[error("invalid input graph: {0}")]
    InvalidInput(String),
    /// Encoded bytes are malformed; `offset` is the byte offset inside the encoded payload.
    #[error("corrupt encoding at payload byte {offset}: {reason}")]
    Corrupt {
        /// Byte offset in the payload.
        offset: u64,
        /// What is wrong.
        reason: String,
    },
}

/// Shorthand for a corrupt-payload error.
pub(crate) fn corrupt(offset: u64, reason: impl Into<String>) -> EncodeError {
    EncodeError::Corrupt {
        offset,
        reason: reason.into(),
    }
}

/// Voxel count and CRC-32 of the Morton-ordered voxel codes (each as 8 little-endian bytes):
/// what `verify` compares a decoded file against.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct VoxelDigest {
    /// Occupied voxels.
    pub voxels: u64,
    /// CRC-32 (IEEE) of the codes in ascending order, 8 little-endian bytes each.
    pub crc32: u32,
}

/// Streaming computation of a [`VoxelDigest`] (codes must come in ascending order).
#[derive(Clone, Default)]
pub struct DigestBuilder {
    hasher: crc32fast::Hasher,
    buffer: Vec<u8>,
    voxels: u64,
}

impl DigestBuilder {
    /// Adds the next code.
    #[inline]
    pub fn push(&mut self, code: u64) {
        self.buffer.extend_from_slice(&code.to_le_bytes());
        self.voxels += 1;
        if self.buffer.len() >= 1 << 15 {
            self.hasher.update(&self.buffer);
            self.buffer.clear();
        }
    }

    /// The digest of every code pushed.
    pub fn finish(mut self) -> VoxelDigest {
        self.hasher.update(&self.buffer);
        VoxelDigest {
            voxels: self.voxels,
            crc32: self.hasher.finalize(),
        }
    }
}

impl VoxelDigest {
    /// Digest of sorted Morton codes (e.g. `Voxels::codes`).
    pub fn of_codes(codes: &[u64]) -> VoxelDigest {
        let mut d = DigestBuilder::default();
        for &c in codes {
            d.push(c);
        }
        d.finish()
    }
}

/// Which node encoding a `.vdag` file stores.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EncodingKind {
    /// 32-bit words (`Svdag`).
    Svdag32,
    /// SSVDAG with 16/32-bit pointers.
    Ssvdag,
    /// TSVDAG.
    Tsvdag,
}

impl EncodingKind {
    /// The CLI name (`svdag32`, `ssvdag`, `tsvdag`).
    pub fn name(self) -> &'static str {
        match self {
            EncodingKind::Svdag32 => "svdag32",
            EncodingKind::Ssvdag => "ssvdag",
            EncodingKind::Tsvdag => "tsvdag",
        }
    }
}

/// A DAG in one of the encodings.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EncodedDag {
    /// Plain SVDAG words.
    Svdag32(crate::dag::Svdag),
    /// SSVDAG bytes.
    Ssvdag(SsvdagEncoding),
    /// TSVDAG bytes.
    Tsvdag(TsvdagEncoding),
}

impl EncodedDag {
    /// The encoding.
    pub fn kind(&self) -> EncodingKind {
        match self {
            EncodedDag::Svdag32(_) => EncodingKind::Svdag32,
            EncodedDag::Ssvdag(_) => EncodingKind::Ssvdag,
            EncodedDag::Tsvdag(_) => EncodingKind::Tsvdag,
        }
    }

    /// Grid side length.
    pub fn resolution(&self) -> u32 {
        match self {
            EncodedDag::Svdag32(d) => d.resolution,
            EncodedDag::Ssvdag(d) => d.resolution,
            EncodedDag::Tsvdag(d) => d.resolution,
        }
    }

    /// Size of the node data in bytes (what `stats` reports per encoding).
    pub fn byte_size(&self) -> u64 {
        match self {
            EncodedDag::Svdag32(d) => d.words.len() as u64 * 4,
            EncodedDag::Ssvdag(d) => d.byte_size(),
            EncodedDag::Tsvdag(d) => d.byte_size(),
        }
    }

    /// Whether voxel (x, y, z) is set, read from the encoded bytes.
    pub fn contains(&self, x: u32, y: u32, z: u32) -> Result<bool, EncodeError> {
        match self {
            EncodedDag::Svdag32(d) => Ok(d.contains(x, y, z)),
            EncodedDag::Ssvdag(d) => contains(d, x, y, z),
            EncodedDag::Tsvdag(d) => d.contains(x, y, z),
        }
    }

    /// Digest of the voxels, by traversal of the encoded bytes.
    pub fn digest(&self) -> Result<VoxelDigest, EncodeError> {
        match self {
            EncodedDag::Svdag32(d) => voxel_digest(d),
            EncodedDag::Ssvdag(d) => voxel_digest(d),
            EncodedDag::Tsvdag(d) => voxel_digest(d),
        }
    }

    /// Every voxel code in ascending Morton order (boxed iterator over the encoded bytes).
    pub fn voxels(&self) -> Box<dyn Iterator<Item = Result<u64, EncodeError>> + '_> {
        match self {
            EncodedDag::Svdag32(d) => Box::new(VoxelIter::new(d)),
            EncodedDag::Ssvdag(d) => Box::new(VoxelIter::new(d)),
            EncodedDag::Tsvdag(d) => Box::new(VoxelIter::new(d)),
        }
    }

    /// First voxel ray hit, traversing the encoded bytes.
    pub fn raycast(
        &self,
        ray: &crate::dag::raycast::Ray,
        t_max: f32,
    ) -> Result<Option<EncodedHit>, EncodeError> {
        match self {
            EncodedDag::Svdag32(d) => raycast(d, ray, t_max),
            EncodedDag::Ssvdag(d) => raycast(d, ray, t_max),
            EncodedDag::Tsvdag(d) => raycast(d, ray, t_max),
        }
    }

    /// Bounding box of the occupied coarse nodes (as `Svdag::occupied_bounds`).
    pub fn occupied_bounds(&self) -> Result<Option<Bounds>, EncodeError> {
        match self {
            EncodedDag::Svdag32(d) => Ok(d.occupied_bounds()),
            EncodedDag::Ssvdag(d) => occupied_bounds(d),
            EncodedDag::Tsvdag(d) => occupied_bounds(d),
        }
    }

    /// Decodes to an SVDAG (colours are not part of the node encoding: pass them separately).
    pub fn to_svdag(&self, colors: Vec<u32>) -> Result<crate::dag::Svdag, EncodeError> {
        match self {
            EncodedDag::Svdag32(d) => {
                let mut d = d.clone();
                d.colors = colors;
                Ok(d)
            }
            EncodedDag::Ssvdag(d) => to_svdag(d, colors),
            EncodedDag::Tsvdag(d) => to_svdag(d, colors),
        }
    }

    /// The encoded payload bytes (svdag32: the words, little-endian).
    pub fn payload(&self) -> Vec<u8> {
        match self {
            EncodedDag::Svdag32(d) => d.words.iter().flat_map(|w| w.to_le_bytes()).collect(),
            EncodedDag::Ssvdag(d) => d.to_payload(),
            EncodedDag::Tsvdag(d) => d.to_payload(),
        }
    }
}
