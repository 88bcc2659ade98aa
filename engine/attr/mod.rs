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

pub mod chunks;
pub mod dado;
pub mod dolonius;
pub mod lossless;
pub mod lossy;
pub mod materials;
pub mod raw;
pub mod varbit;

use serde::{Deserialize, Serialize};

pub use chunks::{ChunkOp, ChunkedColors, StoredColors};
pub use lossless::LosslessVariant;
pub use materials::Materials;

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
    /// Chunk tables that break their invariants, or colours that do not fit the DAG.
    #[error("invalid colour chunks: {0}")]
    Invalid(String),
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

/// Default per-channel error threshold of the lossy encoders (colours in [0, 1]).
pub const DEFAULT_THRESHOLD: f32 = lossy::DEFAULT_THRESHOLD;

/// Run-time choice of colour encoder (the CLI's `--colors` values).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ColorCodec {
    /// Uncompressed RGBA8 words.
    Raw,
    /// The real-time lossless block codec (§5.2.1).
    Lossless(LosslessVariant),
    /// The real-time Hough lossy encoder (§5.2.2), Dolonius et al. format.
    Lossy {
        /// Per-channel error bound, colours in [0, 1].
        threshold: f32,
    },
    /// The offline Dolonius et al. encoder (baseline), same format.
    Dolonius {
        /// Per-channel error bound, colours in [0, 1].
        threshold: f32,
    },
    /// Dado et al. per-block palettes (lossless baseline).
    Dado,
}

impl ColorCodec {
    /// Parses the CLI spelling: `raw|lossless|lossless565|lossy[=T]|dolonius[=T]|dado`
    /// (T: per-channel error threshold in (0, 1], default [`DEFAULT_THRESHOLD`]).
    pub fn parse(text: &str) -> Result<ColorCodec, String> {
        let (name, value) = match text.split_once('=') {
            Some((n, v)) => (n, Some(v)),
            None => (text, None),
        };
        let threshold = |value: Option<&str>| -> Result<f32, String> {
            let Some(v) = value else {
                return Ok(DEFAULT_THRESHOLD);
            };
            let t: f32 = v
                .trim()
                .parse()
                .map_err(|e| format!("bad threshold {v:?}: {e}"))?;
            if !(t > 0.0 && t <= 1.0) {
                return Err(format!("threshold {t} not in (0, 1]"));
            }
            Ok(t)
        };
        let no_value = |codec: ColorCodec| match value {
            None => Ok(codec),
            Some(_) => Err(format!("colour codec {name:?} takes no threshold")),
        };
        match name {
            "raw" => no_value(ColorCodec::Raw),
            "lossless" => no_value(ColorCodec::Lossless(LosslessVariant::Rgb888)),
            "lossless565" => no_value(ColorCodec::Lossless(LosslessVariant::Rgb565)),
            "lossy" => Ok(ColorCodec::Lossy {
                threshold: threshold(value)?,
            }),
            "dolonius" => Ok(ColorCodec::Dolonius {
                threshold: threshold(value)?,
            }),
            "dado" => no_value(ColorCodec::Dado),
            _ => Err(format!(
                "unknown colour codec {text:?}: expected raw, lossless, lossless565, \
                 lossy[=T], dolonius[=T] or dado"
            )),
        }
    }

    /// The CLI spelling (with the threshold of the lossy encoders).
    pub fn name(&self) -> String {
        match self {
            ColorCodec::Raw => "raw".into(),
            ColorCodec::Lossless(LosslessVariant::Rgb888) => "lossless".into(),
            ColorCodec::Lossless(LosslessVariant::Rgb565) => "lossless565".into(),
            ColorCodec::Lossy { threshold } => format!("lossy={threshold}"),
            ColorCodec::Dolonius { threshold } => format!("dolonius={threshold}"),
            ColorCodec::Dado => "dado".into(),
        }
    }

    /// Stable numeric id of the encoder, stored in `.vdag` files so a chunk can be re-encoded
    /// the same way after an edit.
    pub fn id(&self) -> u32 {
        match self {
            ColorCodec::Raw => 0,
            ColorCodec::Lossless(LosslessVariant::Rgb888) => 1,
            ColorCodec::Lossless(LosslessVariant::Rgb565) => 2,
            ColorCodec::Lossy { .. } => 3,
            ColorCodec::Dolonius { .. } => 4,
            ColorCodec::Dado => 5,
        }
    }

    /// The largest per-channel error the codec promises, colours in [0, 1]: 0 for the exact
    /// codecs, 4/255 for RGB565 (round to nearest, expand by bit replication), the threshold for
    /// the lossy encoders.
    pub fn threshold(&self) -> f32 {
        match self {
            ColorCodec::Raw | ColorCodec::Lossless(LosslessVariant::Rgb888) => 0.0,
            ColorCodec::Lossless(LosslessVariant::Rgb565) => 4.0 / 255.0,
            ColorCodec::Lossy { threshold } | ColorCodec::Dolonius { threshold } => *threshold,
            ColorCodec::Dado => 0.0,
        }
    }

    /// The encoder with stored `id` and `threshold`, if valid.
    pub fn from_id(id: u32, threshold: f32) -> Option<ColorCodec> {
        let valid = threshold > 0.0 && threshold <= 1.0;
        match id {
            0 => Some(ColorCodec::Raw),
            1 => Some(ColorCodec::Lossless(LosslessVariant::Rgb888)),
            2 => Some(ColorCodec::Lossless(LosslessVariant::Rgb565)),
            3 if valid => Some(ColorCodec::Lossy { threshold }),
            4 if valid => Some(ColorCodec::Dolonius { threshold }),
            5 => Some(ColorCodec::Dado),
            _ => None,
        }
    }

    /// Stored format of what this encoder writes.
    pub fn format(&self) -> ColorFormat {
        match self {
            ColorCodec::Raw => ColorFormat::Raw,
            ColorCodec::Lossless(LosslessVariant::Rgb888) => ColorFormat::Lossless888,
            ColorCodec::Lossless(LosslessVariant::Rgb565) => ColorFormat::Lossless565,
            ColorCodec::Lossy { .. } | ColorCodec::Dolonius { .. } => ColorFormat::Varbit,
            ColorCodec::Dado => ColorFormat::Palette,
        }
    }

    /// True when decoding returns the input colours exactly (alpha aside).
    pub fn is_exact(&self) -> bool {
        matches!(
            self,
            ColorCodec::Raw | ColorCodec::Lossless(LosslessVariant::Rgb888) | ColorCodec::Dado
        )
    }

    /// Side in voxels of the SVO nodes that default chunks cover: 256 for the exact formats, 128
    /// for the lossy one (whose blocks need no per-chunk palette, so smaller chunks cost little).
    pub fn default_chunk_side(&self) -> u32 {
        if self.format() == ColorFormat::Varbit {
            128
        } else {
            256
        }
    }

    /// Default chunk depth below the root (§5.1) for a grid of side `resolution`: the depth whose
    /// nodes are `default_chunk_side()` voxels wide (0 when the grid is smaller). At a 32K^3 grid
    /// this is the dissertation's 7 (exact) and 8 (lossy); a fixed depth would make chunks of a
    /// few voxels at smaller grids, where per-chunk tables swamp the codecs (docs/colors.md).
    pub fn default_chunk_depth(&self, resolution: u32) -> u32 {
        resolution
            .max(1)
            .ilog2()
            .saturating_sub(self.default_chunk_side().ilog2())
    }

    /// Encodes one chunk of colours.
    pub fn encode(&self, colors: &[u32]) -> Vec<u32> {
        match self {
            ColorCodec::Raw => raw::encode(colors),
            ColorCodec::Lossless(variant) => lossless::encode(colors, *variant),
            ColorCodec::Lossy { threshold } => lossy::encode(colors, *threshold),
            ColorCodec::Dolonius { threshold } => dolonius::encode(colors, *threshold),
            ColorCodec::Dado => dado::encode(colors),
        }
    }
}

/// Every colour of a chunk of `count` colours stored in `format`.
pub fn decode_all(format: ColorFormat, words: &[u32], count: usize) -> Result<Vec<u32>, AttrError> {
    match format {
        ColorFormat::Raw => raw::decode_all(words, count),
        ColorFormat::Lossless888 | ColorFormat::Lossless565 => lossless::decode_all(words, count),
        ColorFormat::Varbit => varbit::decode_all(words, count),
        ColorFormat::Palette => dado::decode_all(words, count),
    }
}

/// Colour `index` of a chunk of `count` colours stored in `format` (random access).
pub fn decode(
    format: ColorFormat,
    words: &[u32],
    count: usize,
    index: usize,
) -> Result<u32, AttrError> {
    match format {
        ColorFormat::Raw => raw::decode(words, count, index),
        ColorFormat::Lossless888 | ColorFormat::Lossless565 => {
            lossless::decode(words, count, index)
        }
        ColorFormat::Varbit => varbit::decode(words, count, index),
        ColorFormat::Palette => dado::decode(words, count, index),
    }
}

/// RMSE of `decoded` against `reference`, RGB channels in [0, 1] (0 for two empty slices).
pub fn rmse(reference: &[u32], decoded: &[u32]) -> f64 {
    let n = reference.len().min(decoded.len());
    if n == 0 {
        return 0.0;
    }
    let sum: f64 = reference
        .iter()
        .zip(decoded)
        .map(|(&a, &b)| squared_error(a, b))
        .sum();
    (sum / (3 * n) as f64).sqrt()
}

/// Sum over R, G, B of the squared difference in [0, 1] units: one colour's term of [`rmse`]
/// (the streaming build sums these in the same order to get the same bits).
pub fn squared_error(a: u32, b: u32) -> f64 {
    let (a, b) = (rgb(a), rgb(b));
    (0..3)
        .map(|k| {
            let d = (a[k] as f64 - b[k] as f64) / 255.0;
            d * d
        })
        .sum::<f64>()
}

/// Largest per-channel difference between `reference` and `decoded`, in [0, 1].
pub fn max_channel_error(reference: &[u32], decoded: &[u32]) -> f32 {
    reference
        .iter()
        .zip(decoded)
        .flat_map(|(&a, &b)| {
            let (a, b) = (rgb(a), rgb(b));
            (0..3).map(move |k| a[k].abs_diff(b[k]))
        })
        .max()
        .unwrap_or(0) as f32
        / 255.0
}
