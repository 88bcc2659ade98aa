//! The offline lossy colour encoder of Dolonius et al. 2017 (the baseline of the Hough encoder),
//! written in the same variable-bitrate format (`varbit`) under the same per-channel threshold.
//!
//! For every colour position `i` and every bit width b (0 = single colour, 1-4 bits per weight)
//! it finds the longest block starting at `i` that b bits can hold: the block's line is the
//! least-squares fit of its colours (mean and principal axis of their covariance, endpoints at
//! the extreme projections), and a block fits when every decoded colour, after RGB565 endpoint
//! quantization, is within the threshold. Each length search starts from the previous
//! position's length minus one, grows one colour at a time while the block still fits and
//! shrinks while it does not. A dynamic program over the positions then picks the cut into
//! blocks of least total size (64 header bits + b bits per colour) from these candidates.
//! Macro blocks are encoded in parallel.
//!
//! Every candidate block is refitted and checked, so the threshold promise holds exactly as for
//! the Hough encoder; the price is many least-squares fits per colour, which is what makes this
//! encoder slow.

use rayon::prelude::*;

use super::rgb;
use super::varbit::{self, VarbitBlock, MACRO_BLOCK_COLORS};

/// Longest block considered, in colours; bounds the quadratic cost on flat colour runs (a longer
/// run saves at most one 64-bit header per `MAX_BLOCK` colours).
pub const MAX_BLOCK: usize = 256;
/// Bits of a block header in the size the cut minimizes.
const HEADER_BITS: usize = 64;
/// Bit widths tried; 0 is a single-colour block.
const WIDTHS: [u8; 5] = [0, 1, 2, 3, 4];

/// Encodes RGBA8 colours (alpha ignored) so that every decoded channel is within `threshold`
/// (colours in [0, 1]; more precisely within `varbit::max_delta(threshold)` 8-bit steps).
pub fn encode(colors: &[u32], threshold: f32) -> Vec<u32> {
    varbit::write(&encode_blocks(colors, threshold), colors.len())
        .expect("the offline encoder emits sorted blocks that cover every colour")
}

/// The block list `encode` writes.
pub fn encode_blocks(colors: &[u32], threshold: f32) -> Vec<VarbitBlock> {
    let max_delta = varbit::max_delta(threshold);
    let rgb: Vec<[u8; 3]> = colors.iter().map(|&c| rgb(c)).collect();
    rgb.par_chunks(MACRO_BLOCK_COLORS)
        .enumerate()
        .map(|(m, chunk)| encode_macro_block(chunk, m * MACRO_BLOCK_COLORS, max_delta))
        .collect::<Vec<_>>()
        .concat()
}

fn encode_macro_block(colors: &[[u8; 3]], offset: usize, max_delta: u8) -> Vec<VarbitBlock> {
    let n = colors.len();
    // longest[i][b]: the longest block at i that width b holds (0 when none, never for b = 0).
    let mut longest = vec![[0usize; WIDTHS.len()]; n];
    for (w, &bits) in WIDTHS.iter().enumerate() {
        let mut len = 1;
        for i in 0..n {
            let max_len = (n - i).min(MAX_BLOCK);
            len = len.clamp(1, max_len);
            while len > 0 && fit(&colors[i..i + len], 0, bits, max_delta).is_none() {
                len -= 1;
            }
            while len > 0
                && len < max_len
                && fit(&colors[i..=i + len], 0, bits, max_delta).is_some()
            {
                len += 1;
            }
            longest[i][w] = len;
            len = len.saturating_sub(1);
        }
    }
    // cost[i]: least bits for colours i..n; choice[i]: the width index that achieves it.
    let mut cost = vec![0usize; n + 1];
    let mut choice = vec![0usize; n];
    for i in (0..n).rev() {
        cost[i] = usize::MAX;
        for (w, &bits) in WIDTHS.iter().enumerate() {
            let len = longest[i][w];
            if len == 0 {
                continue;
            }
            let c = HEADER_BITS + usize::from(bits) * len + cost[i + len];
            if c < cost[i] {
                cost[i] = c;
                choice[i] = w;
            }
        }
    }
    let mut blocks = Vec::new();
    let mut i = 0;
    while i < n {
        let w = choice[i];
        let len = longest[i][w];
        let block = fit(&colors[i..i + len], offset + i, WIDTHS[w], max_delta)
            .expect("the length search verified this block");
        blocks.push(block);
        i += len;
    }
    blocks
}

/// The block of `colors` with exactly `bits` bits per weight (0: single colour) on their
/// least-squares line, if every colour decodes within `max_delta`.
fn fit(colors: &[[u8; 3]], start: usize, bits: u8, max_delta: u8) -> Option<VarbitBlock> {
    if bits == 0 {
        return varbit::single_block(colors, start, max_delta);
    }
    varbit::endpoint_block(
        colors,
        start,
        least_squares_line(colors),
        bits..=bits,
        max_delta,
    )
    .ok()
}

/// Endpoints (channels in [0, 255]) of the least-squares line of `colors`: through their mean
/// along the principal axis of their covariance (power iteration), spanning their projections.
fn least_squares_line(colors: &[[u8; 3]]) -> [[f32; 3]; 2] {
    let n = colors.len() as f32;
    let mut mean = [0.0f32; 3];
    for c in colors {
        for k in 0..3 {
            mean[k] += f32::from(c[k]);
        }
    }
    mean = mean.map(|v| v / n);
    let mut cov = [[0.0f32; 3]; 3];
    for c in colors {
        let d = [0, 1, 2].map(|k| f32::from(c[k]) - mean[k]);
        for r in 0..3 {
            for s in 0..3 {
                cov[r][s] += d[r] * d[s];
            }
        }
    }
    // Start from the axis of largest variance so that power iteration cannot start orthogonal.
    let start = (0..3)
        .max_by(|&a, &b| cov[a][a].total_cmp(&cov[b][b]))
        .unwrap_or(0);
    let mut axis = [0.0f32; 3];
    axis[start] = 1.0;
    for _ in 0..8 {
        let next = [0, 1, 2].map(|r| (0..3).map(|s| cov[r][s] * axis[s]).sum::<f32>());
        let len = next.iter().map(|v| v * v).sum::<f32>().sqrt();
        if len <= f32::EPSILON {
            break;
        }
        axis = next.map(|v| v / len);
    }
    let (mut t_min, mut t_max) = (f32::INFINITY, f32::NEG_INFINITY);
    for c in colors {
        let t: f32 = (0..3).map(|k| (f32::from(c[k]) - mean[k]) * axis[k]).sum();
        t_min = t_min.min(t);
        t_max = t_max.max(t);
    }
    let at = |t: f32| [0, 1, 2].map(|k| mean[k] + t * axis[k]);
    [at(t_min), at(t_max)]
}
