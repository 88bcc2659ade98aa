//! Decoupled attributes (dissertation §5.1): the colours of the occupied voxels in depth-first
//! Morton order (= `Svdag::colors`), split into chunks, one per SVO node at a chosen depth below
//! the root, each encoded on its own. An edit re-encodes only the chunks it touches
//! ([`ChunkedColors::rebuild`] from a stream of [`ChunkOp`]s, §5.3), and a colour is found by a
//! binary search of the chunk table followed by the format's random access.

use std::ops::Range;

use indicatif::ProgressBar;
use rayon::prelude::*;

use super::{decode, decode_all, AttrError, ColorCodec, ColorFormat};
use crate::dag::{Svdag, VoxelIndex};

/// Most colours one chunk may hold (GPU colour indices are `uint`).
pub const MAX_CHUNK_COLORS: u64 = u32::MAX as u64;

/// Encoded colours split into independently decodable chunks.
#[derive(Clone, Debug, PartialEq)]
pub struct ChunkedColors {
    /// The encoder that wrote the chunks (used again by [`ChunkedColors::rebuild`]).
    pub codec: ColorCodec,
    /// Stored format of every chunk (`codec.format()`).
    pub format: ColorFormat,
    /// Depth below the root of the SVO nodes that own one chunk each (root = 0).
    pub chunk_depth: u32,
    /// First colour index of each chunk, then the total colour count (chunks + 1 entries).
    pub chunk_starts: Vec<u64>,
    /// First word of each chunk in `words`, then `words.len()` (chunks + 1 entries).
    pub chunk_offsets: Vec<u64>,
    /// The encoded words of all chunks, back to back.
    pub words: Vec<u32>,
}

/// Colours as an encoder stored them: the chunks and the error measured when they were encoded
/// (what a `.vdag` file's chunked colour section holds).
#[derive(Clone, Debug, PartialEq)]
pub struct StoredColors {
    /// The encoded chunks.
    pub chunks: ChunkedColors,
    /// RMSE (RGB in [0, 1]) of the decoded chunks against the voxelizer's colours, measured at
    /// encode time (0 for the exact formats).
    pub rmse: f64,
}

impl StoredColors {
    /// Encodes `dag.colors` (see [`ChunkedColors::build`]) and measures the RMSE of the result.
    pub fn encode(
        dag: &Svdag,
        codec: ColorCodec,
        chunk_depth: Option<u32>,
        bar: &ProgressBar,
    ) -> Result<StoredColors, AttrError> {
        let chunks = ChunkedColors::build(dag, codec, chunk_depth, bar)?;
        let rmse = super::rmse(&dag.colors, &chunks.decode_all()?);
        Ok(StoredColors { chunks, rmse })
    }
}

/// One step of a chunk rebuild: the new colours of a chunk are the concatenation of the steps.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ChunkOp {
    /// `len` colours of the old colour stream from index `from` (kept voxels).
    Copy {
        /// First colour index in the old stream.
        from: u64,
        /// Number of colours.
        len: u64,
    },
    /// `len` copies of one colour (a filled or painted region).
    Fill {
        /// The RGBA8 colour.
        color: u32,
        /// Number of colours.
        len: u64,
    },
    /// Explicit colours.
    Write(Vec<u32>),
}

/// Voxel count of every SVO node at `depth` below the root (clamped to the leaves' depth), in
/// depth-first Morton order: the sizes of the chunks of [`ChunkedColors::build`].
pub fn chunk_sizes(dag: &Svdag, index: &VoxelIndex, depth: u32) -> Vec<u64> {
    let mut sizes = Vec::new();
    if dag.words.first().copied().unwrap_or(0) == 0 {
        return sizes;
    }
    let depth = depth.min(dag.root_level());
    // Depth-first: children pushed in descending octant order so they pop ascending.
    let mut stack = vec![(0usize, 0u32)];
    while let Some((node, d)) = stack.pop() {
        if d == depth {
            sizes.push(index.node_voxels[node]);
            continue;
        }
        for octant in (0..8).rev() {
            if let Some(child) = dag.child(node, octant) {
                stack.push((child, d + 1));
            }
        }
    }
    sizes
}

impl ChunkedColors {
    /// Encodes `dag.colors` with `codec`, one chunk per SVO node at `chunk_depth` (default
    /// [`ColorCodec::default_chunk_depth`]); chunks are encoded in parallel, `bar` counts them.
    pub fn build(
        dag: &Svdag,
        codec: ColorCodec,
        chunk_depth: Option<u32>,
        bar: &ProgressBar,
    ) -> Result<ChunkedColors, AttrError> {
        let depth = chunk_depth
            .unwrap_or_else(|| codec.default_chunk_depth(dag.resolution))
            .min(dag.root_level());
        let sizes = chunk_sizes(dag, &VoxelIndex::new(dag), depth);
        let voxels: u64 = sizes.iter().sum();
        if voxels != dag.colors.len() as u64 {
            return Err(AttrError::Invalid(format!(
                "{} colours for {voxels} voxels",
                dag.colors.len()
            )));
        }
        Self::encode(&dag.colors, &sizes, codec, depth, bar)
    }

    /// Encodes `colors` split into chunks of `sizes` colours (which must sum to the colour count).
    pub fn encode(
        colors: &[u32],
        sizes: &[u64],
        codec: ColorCodec,
        chunk_depth: u32,
        bar: &ProgressBar,
    ) -> Result<ChunkedColors, AttrError> {
        let mut chunk_starts = Vec::with_capacity(sizes.len() + 1);
        let mut start = 0u64;
        chunk_starts.push(0);
        for &n in sizes {
            if n > MAX_CHUNK_COLORS {
                return Err(AttrError::Invalid(format!("chunk of {n} colours")));
            }
            start += n;
            chunk_starts.push(start);
        }
        if start != colors.len() as u64 {
            return Err(AttrError::Invalid(format!(
                "chunk sizes sum to {start}, {} colours given",
                colors.len()
            )));
        }
        bar.set_length(sizes.len() as u64);
        bar.set_message("colours");
        let encoded: Vec<Vec<u32>> = chunk_starts
            .par_windows(2)
            .map(|w| {
                let words = codec.encode(&colors[w[0] as usize..w[1] as usize]);
                bar.inc(1);
                words
            })
            .collect();
        let mut chunk_offsets = Vec::with_capacity(sizes.len() + 1);
        chunk_offsets.push(0);
        let total: usize = encoded.iter().map(Vec::len).sum();
        let mut words = Vec::with_capacity(total);
        for chunk in encoded {
            words.extend_from_slice(&chunk);
            chunk_offsets.push(words.len() as u64);
        }
        Ok(ChunkedColors {
            codec,
            format: codec.format(),
            chunk_depth,
            chunk_starts,
            chunk_offsets,
            words,
        })
    }

    /// Number of chunks.
    pub fn chunk_count(&self) -> usize {
        self.chunk_starts.len().saturating_sub(1)
    }

    /// Number of colours in all chunks.
    pub fn color_count(&self) -> u64 {
        self.chunk_starts.last().copied().unwrap_or(0)
    }

    /// Colour indices of chunk `chunk`.
    pub fn chunk_colors(&self, chunk: usize) -> Range<u64> {
        self.chunk_starts[chunk]..self.chunk_starts[chunk + 1]
    }

    /// The chunk holding colour `index`, if in range.
    pub fn chunk_of(&self, index: u64) -> Option<usize> {
        if index >= self.color_count() {
            return None;
        }
        // The last chunk whose start is <= index (empty chunks are skipped over).
        Some(self.chunk_starts.partition_point(|&s| s <= index) - 1)
    }

    /// Encoded words of chunk `chunk`.
    fn chunk_words(&self, chunk: usize) -> &[u32] {
        &self.words[self.chunk_offsets[chunk] as usize..self.chunk_offsets[chunk + 1] as usize]
    }

    /// Colour `index` (random access: binary search of the chunk, then the format's decoder).
    pub fn color(&self, index: u64) -> Result<u32, AttrError> {
        let chunk = self.chunk_of(index).ok_or(AttrError::IndexOutOfRange {
            index,
            count: self.color_count(),
        })?;
        let range = self.chunk_colors(chunk);
        decode(
            self.format,
            self.chunk_words(chunk),
            (range.end - range.start) as usize,
            (index - range.start) as usize,
        )
    }

    /// Every colour of chunk `chunk`.
    pub fn decode_chunk(&self, chunk: usize) -> Result<Vec<u32>, AttrError> {
        let range = self.chunk_colors(chunk);
        decode_all(
            self.format,
            self.chunk_words(chunk),
            (range.end - range.start) as usize,
        )
    }

    /// Every colour, in order (chunks decoded in parallel).
    pub fn decode_all(&self) -> Result<Vec<u32>, AttrError> {
        let chunks: Vec<Vec<u32>> = (0..self.chunk_count())
            .into_par_iter()
            .map(|c| self.decode_chunk(c))
            .collect::<Result<_, _>>()?;
        Ok(chunks.concat())
    }

    /// Checks the tables (same length, start at 0, monotone, offsets end at `words.len()`, chunks
    /// within [`MAX_CHUNK_COLORS`]) without decoding anything.
    pub fn validate_tables(&self) -> Result<(), AttrError> {
        let bad = |m: String| Err(AttrError::Invalid(m));
        if self.format != self.codec.format() {
            return bad(format!(
                "format {} is not what encoder {} writes",
                self.format.name(),
                self.codec.name()
            ));
        }
        if self.chunk_starts.is_empty() || self.chunk_starts.len() != self.chunk_offsets.len() {
            return bad(format!(
                "{} chunk starts and {} chunk offsets",
                self.chunk_starts.len(),
                self.chunk_offsets.len()
            ));
        }
        if self.chunk_starts[0] != 0 || self.chunk_offsets[0] != 0 {
            return bad("the first chunk does not start at 0".into());
        }
        for (i, w) in self.chunk_starts.windows(2).enumerate() {
            if w[1] < w[0] || w[1] - w[0] > MAX_CHUNK_COLORS {
                return bad(format!("chunk {i} colours {}..{}", w[0], w[1]));
            }
        }
        for (i, w) in self.chunk_offsets.windows(2).enumerate() {
            if w[1] < w[0] {
                return bad(format!("chunk {i} words {}..{}", w[0], w[1]));
            }
        }
        let end = *self.chunk_offsets.last().expect("non-empty");
        if end != self.words.len() as u64 {
            return bad(format!(
                "chunk offsets end at {end}, {} words stored",
                self.words.len()
            ));
        }
        Ok(())
    }

    /// [`ChunkedColors::validate_tables`], then decodes every chunk.
    pub fn validate(&self) -> Result<(), AttrError> {
        self.validate_tables()?;
        (0..self.chunk_count())
            .into_par_iter()
            .try_for_each(|c| self.decode_chunk(c).map(drop))
    }

    /// Bytes of the encoded words plus both tables.
    pub fn byte_size(&self) -> u64 {
        self.words.len() as u64 * 4
            + (self.chunk_starts.len() + self.chunk_offsets.len()) as u64 * 8
    }

    /// Colours `from..from + len` of the current stream, decoding only the chunks they span.
    fn decode_range(&self, from: u64, len: u64) -> Result<Vec<u32>, AttrError> {
        let end = from
            .checked_add(len)
            .filter(|&e| e <= self.color_count())
            .ok_or(AttrError::IndexOutOfRange {
                index: from.saturating_add(len),
                count: self.color_count(),
            })?;
        let mut out = Vec::with_capacity(len as usize);
        let mut at = from;
        while at < end {
            let chunk = self.chunk_of(at).expect("at < color_count");
            let range = self.chunk_colors(chunk);
            let colors = self.decode_chunk(chunk)?;
            let stop = end.min(range.end);
            out.extend_from_slice(
                &colors[(at - range.start) as usize..(stop - range.start) as usize],
            );
            at = stop;
        }
        Ok(out)
    }

    /// Replaces chunk `chunk` by the colours `ops` produce from the current colour stream (every
    /// `Copy` reads the stream as it was before this call), re-encoding only that chunk: its words
    /// are spliced in and the later chunks' starts and offsets shift.
    pub fn rebuild(&mut self, chunk: usize, ops: &[ChunkOp]) -> Result<(), AttrError> {
        if chunk >= self.chunk_count() {
            return Err(AttrError::Invalid(format!(
                "chunk {chunk} of {}",
                self.chunk_count()
            )));
        }
        let new_len = ops.iter().try_fold(0u64, |n, op| {
            let len = match op {
                ChunkOp::Copy { len, .. } | ChunkOp::Fill { len, .. } => *len,
                ChunkOp::Write(colors) => colors.len() as u64,
            };
            n.checked_add(len).filter(|&n| n <= MAX_CHUNK_COLORS)
        });
        let new_len = new_len.ok_or_else(|| {
            AttrError::Invalid(format!(
                "rebuilt chunk {chunk} would exceed {MAX_CHUNK_COLORS} colours"
            ))
        })?;
        let mut colors = Vec::with_capacity(new_len as usize);
        for op in ops {
            match op {
                ChunkOp::Copy { from, len } => {
                    colors.extend_from_slice(&self.decode_range(*from, *len)?)
                }
                ChunkOp::Fill { color, len } => colors.resize(colors.len() + *len as usize, *color),
                ChunkOp::Write(c) => colors.extend_from_slice(c),
            }
        }
        let encoded = self.codec.encode(&colors);
        let words = self.chunk_offsets[chunk] as usize..self.chunk_offsets[chunk + 1] as usize;
        let (old_words, old_colors) = (words.len() as u64, self.chunk_colors(chunk));
        self.words.splice(words, encoded.iter().copied());
        let old_len = old_colors.end - old_colors.start;
        for i in chunk + 1..self.chunk_starts.len() {
            self.chunk_starts[i] = self.chunk_starts[i] - old_len + new_len;
            self.chunk_offsets[i] = self.chunk_offsets[i] - old_words + encoded.len() as u64;
        }
        Ok(())
    }
}
