//! Per-voxel attributes: the colours of the occupied voxels in depth-first Morton order (the
//! order `dag::VoxelIndex` turns a traversal path into), split into chunks, and the colour
//! codecs. CPU only: these are the references of the GPU passes in `attr_gpu` and of the GLSL
//! decoders in `shaders/glsl/attr/`.
//!
//! Colours are RGBA8 words `r | g << 8 | b << 16 | a << 24` (sRGB). The codecs store RGB only:
//! every decoder returns alpha 255.
//!
//! # The codec contract
//! Every stored format encodes one chunk of colours into self-contained little-endian `u32` words
//! (uploaded to the GPU unchanged; 64-bit fields are two words, low word first). The number of
//! colours in a chunk is known from the chunk table, so a format need not store it, and each
//! format module offers:
//! - `encode(colors: &[u32], ..) -> Vec<u32>` (encoder parameters differ per codec),
//! - `decode_all(words: &[u32], count: usize) -> Result<Vec<u32>, AttrError>`,
//! - `decode(words: &[u32], count: usize, index: usize) -> Result<u32, AttrError>` (random access),
//!
//! and decoding never panics on corrupt words: it returns `AttrError::Corrupt`.

pub mod lossless;

use serde::{Deserialize, Serialize};

/// Stored format of an encoded colour chunk; the ids are part of the `.vdag` format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u32)]
pub enum ColorFormat {
    /// One RGBA8 word per colour (HashDAG's edit-time storage).
    Raw = 0,
    /// Lossless block codec (§5.2.1), RGB888.
    Lossless888 = 1,
    /// Lossless block codec (§5.2.1) on colours quantized to RGB565.
    Lossless565 = 2,
    /// Dolonius et al. variable-bitrate blocks (written by the Hough and the offline encoders).
    Varbit = 3,
    /// Dado et al. per-block palettes.
    Palette = 4,
}

impl ColorFormat {
    /// Every format, in id order.
    pub const ALL: [ColorFormat; 5] = [
        ColorFormat::Raw,
        ColorFormat::Lossless888,
        ColorFormat::Lossless565,
        ColorFormat::Varbit,
        ColorFormat::Palette,
    ];

    /// The format with stored id `id`, if any.
    pub fn from_id(id: u32) -> Option<ColorFormat> {
        ColorFormat::ALL.into_iter().find(|f| *f as u32 == id)
    }

    /// Short lowercase name used in logs, JSON and file listings.
    pub fn name(self) -> &'static str {
        match self {
            ColorFormat::Raw => "raw",
            ColorFormat::Lossless888 => "lossless",
            ColorFormat::Lossless565 => "lossless565",
            ColorFormat::Varbit => "varbit",
            ColorFormat::Palette => "palette",
        }
    }
}

/// Errors of colour decoding and chunk handling.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AttrError {
    /// Encoded words break the format; `word` is the offset of the offending field.
    #[error("corrupt {format} colour data at word {word}: {reason}")]
    Corrupt {
        /// Name of the stored format.
        format: &'static str,
        /// Word offset inside the chunk.
        word: u64,
        /// What is wrong.
        reason: String,
    },
    /// A colour index past the end of the chunk.
    #[error("colour index {index} out of range (chunk holds {count} colours)")]
    IndexOutOfRange {
        /// Requested index.
        index: u64,
        /// Colours in the chunk.
        count: u64,
    },
}

/// The RGB channels of an RGBA8 word as `[r, g, b]`.
pub fn rgb(color: u32) -> [u8; 3] {
    [color as u8, (color >> 8) as u8, (color >> 16) as u8]
}

/// An opaque RGBA8 word from `[r, g, b]`.
pub fn pack_rgb([r, g, b]: [u8; 3]) -> u32 {
    r as u32 | (g as u32) << 8 | (b as u32) << 16 | 0xff00_0000
}

pub mod dado;
pub mod dolonius;
pub mod lossy;
pub mod varbit;
