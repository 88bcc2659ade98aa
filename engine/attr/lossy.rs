//! The real-time lossy colour encoder (dissertation §5.2.2): one greedy pass over the colour
//! stream that fits line segments with the continuous Hough transform, written in the Dolonius et
//! al. variable-bitrate format (`varbit`).
//!
//! A segment grows one colour at a time. Each of the three planes RG, GB and RB keeps, for
//! [`THETA_STEPS`] line angles θ, the range [ρmin, ρmax] of `ρ = x cos θ + y sin θ` over the
//! segment's colours (channels in [0, 1]); an angle is dropped once ρmax - ρmin exceeds twice the
//! Hough band (a line at that angle can no longer pass within the band of every colour). The
//! segment ends before the colour that would leave some plane without angles. The 3D line is then
//! rebuilt from the two planes whose colours spread widest, the colours are projected on it, and
//! `varbit::endpoint_block` picks the fewest bits (1-4) whose decoded colours, after RGB565
//! endpoint quantization, all stay within the threshold; a segment that fails even with 4 bits is
//! cut before its first failing colour and refitted. Segments within the threshold of one colour
//! become single-colour blocks. Macro blocks are encoded in parallel.

use rayon::prelude::*;

use super::rgb;
use super::varbit::{self, VarbitBlock, MACRO_BLOCK_COLORS};

/// The default per-channel error threshold (colours in [0, 1]).
pub const DEFAULT_THRESHOLD: f32 = 0.06;
/// Number of line angles θ per plane, evenly spaced over [0, π).
pub const THETA_STEPS: usize = 64;
/// Half-width of the Hough band as a fraction of the threshold: the rest of the threshold is left
/// to the weight quantization along the line.
const BAND_FRACTION: f32 = 0.5;

/// Encodes RGBA8 colours (alpha ignored) so that every decoded channel is within `threshold`
/// (colours in [0, 1]; more precisely within `varbit::max_delta(threshold)` 8-bit steps) of the
/// input.
pub fn encode(colors: &[u32], threshold: f32) -> Vec<u32> {
    varbit::write(&encode_blocks(colors, threshold), colors.len())
        .expect("the Hough encoder emits sorted blocks that cover every colour")
}

/// The block list `encode` writes.
pub fn encode_blocks(colors: &[u32], threshold: f32) -> Vec<VarbitBlock> {
    let max_delta = varbit::max_delta(threshold);
    let band = f32::from(max_delta) / 255.0 * BAND_FRACTION;
    let rgb: Vec<[u8; 3]> = colors.iter().map(|&c| rgb(c)).collect();
    let angles = Angles::new();
    rgb.par_chunks(MACRO_BLOCK_COLORS)
        .enumerate()
        .map(|(m, chunk)| {
            encode_macro_block(chunk, m * MACRO_BLOCK_COLORS, band, max_delta, &angles)
        })
        .collect::<Vec<_>>()
        .concat()
}

fn encode_macro_block(
    colors: &[[u8; 3]],
    offset: usize,
    band: f32,
    max_delta: u8,
    angles: &Angles,
) -> Vec<VarbitBlock> {
    let mut blocks = Vec::new();
    let mut hough = Hough::new(angles, band);
    let mut i = 0;
    while i < colors.len() {
        let mut limit = colors.len();
        loop {
            let end = hough.segment(&colors[i..limit]) + i;
            let segment = &colors[i..end];
            if let Some(block) = varbit::single_block(segment, offset + i, max_delta) {
                blocks.push(block);
                i = end;
                break;
            }
            let line = hough.line(segment);
            match varbit::endpoint_block(segment, offset + i, line, 1..=4, max_delta) {
                Ok(block) => {
                    blocks.push(block);
                    i = end;
                    break;
                }
                // A one-colour segment always fits a single block, so `end - i >= 2` here.
                Err(0) => limit = i + (end - i) / 2,
                Err(fail) => limit = i + fail,
            }
        }
    }
    blocks
}

/// cos θ and sin θ of the angle steps.
struct Angles {
    cos: [f32; THETA_STEPS],
    sin: [f32; THETA_STEPS],
}

impl Angles {
    fn new() -> Angles {
        let theta = |k: usize| k as f32 * std::f32::consts::PI / THETA_STEPS as f32;
        Angles {
            cos: std::array::from_fn(|k| theta(k).cos()),
            sin: std::array::from_fn(|k| theta(k).sin()),
        }
    }
}

/// Channel pairs (x, y) of the three planes RG, GB, RB.
const PLANES: [(usize, usize); 3] = [(0, 1), (1, 2), (0, 2)];

/// Per-plane state of the growing segment.
struct Plane {
    rho_min: [f32; THETA_STEPS],
    rho_max: [f32; THETA_STEPS],
    /// Angle steps still within the band.
    alive: Vec<u8>,
    /// Surviving angles if the candidate colour is accepted.
    next_alive: Vec<u8>,
}

/// The Hough state of one segment and the band it must stay in.
struct Hough<'a> {
    angles: &'a Angles,
    band: f32,
    planes: [Plane; 3],
}

impl<'a> Hough<'a> {
    fn new(angles: &'a Angles, band: f32) -> Hough<'a> {
        let plane = || Plane {
            rho_min: [0.0; THETA_STEPS],
            rho_max: [0.0; THETA_STEPS],
            alive: Vec::with_capacity(THETA_STEPS),
            next_alive: Vec::with_capacity(THETA_STEPS),
        };
        Hough {
            angles,
            band,
            planes: [plane(), plane(), plane()],
        }
    }

    /// Length of the longest prefix of `colors` (at least 1) that every plane keeps an angle
    /// for; the state then describes that prefix.
    fn segment(&mut self, colors: &[[u8; 3]]) -> usize {
        let unit = |c: [u8; 3]| c.map(|v| f32::from(v) / 255.0);
        let first = unit(colors[0]);
        for (plane, &(x, y)) in self.planes.iter_mut().zip(&PLANES) {
            plane.alive.clear();
            plane.alive.extend(0..THETA_STEPS as u8);
            for k in 0..THETA_STEPS {
                let rho = first[x] * self.angles.cos[k] + first[y] * self.angles.sin[k];
                plane.rho_min[k] = rho;
                plane.rho_max[k] = rho;
            }
        }
        let width = 2.0 * self.band;
        for (n, &c) in colors.iter().enumerate().skip(1) {
            let p = unit(c);
            // First find the survivors in every plane; commit only if no plane runs out.
            for (plane, &(x, y)) in self.planes.iter_mut().zip(&PLANES) {
                plane.next_alive.clear();
                for &k in &plane.alive {
                    let k = k as usize;
                    let rho = p[x] * self.angles.cos[k] + p[y] * self.angles.sin[k];
                    if plane.rho_max[k].max(rho) - plane.rho_min[k].min(rho) <= width {
                        plane.next_alive.push(k as u8);
                    }
                }
                if plane.next_alive.is_empty() {
                    return n;
                }
            }
            for (plane, &(x, y)) in self.planes.iter_mut().zip(&PLANES) {
                std::mem::swap(&mut plane.alive, &mut plane.next_alive);
                for &k in &plane.alive {
                    let k = k as usize;
                    let rho = p[x] * self.angles.cos[k] + p[y] * self.angles.sin[k];
                    plane.rho_min[k] = plane.rho_min[k].min(rho);
                    plane.rho_max[k] = plane.rho_max[k].max(rho);
                }
            }
        }
        colors.len()
    }

    /// Endpoints (channels in [0, 255]) of the segment `colors` that `segment` just measured: the
    /// 3D line where the best lines of the two widest-spread planes meet, clipped to the
    /// colours' projections.
    fn line(&self, colors: &[[u8; 3]]) -> [[f32; 3]; 2] {
        let mut lo = [255u8; 3];
        let mut hi = [0u8; 3];
        for c in colors {
            for k in 0..3 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
        let range = |k: usize| f32::from(hi[k] - lo[k]) / 255.0;
        // Normal (in 3D) and ρ of each plane's best line: its narrowest surviving angle.
        let best: [([f32; 3], f32); 3] = std::array::from_fn(|p| {
            let plane = &self.planes[p];
            let k = *plane
                .alive
                .iter()
                .min_by(|&&a, &&b| {
                    let width = |k: u8| plane.rho_max[k as usize] - plane.rho_min[k as usize];
                    width(a).total_cmp(&width(b))
                })
                .unwrap_or(&0) as usize;
            let (x, y) = PLANES[p];
            let mut normal = [0.0; 3];
            normal[x] = self.angles.cos[k];
            normal[y] = self.angles.sin[k];
            (normal, (plane.rho_min[k] + plane.rho_max[k]) / 2.0)
        });
        let spread = |p: usize| range(PLANES[p].0).hypot(range(PLANES[p].1));
        let mut order = [0usize, 1, 2];
        order.sort_by(|&a, &b| spread(b).total_cmp(&spread(a)));
        // Widest pair first; a pair whose lines are parallel in 3D gives no line: try the next.
        let pairs = [
            (order[0], order[1]),
            (order[0], order[2]),
            (order[1], order[2]),
        ];
        let unit = |c: &[u8; 3]| c.map(|v| f32::from(v) / 255.0);
        for (p, q) in pairs {
            let ((n1, r1), (n2, r2)) = (best[p], best[q]);
            let dir = cross(n1, n2);
            let dir_len2 = dot(dir, dir);
            if dir_len2 < 1e-6 {
                continue;
            }
            // The point of the line nearest the origin: a n1 + b n2 with n·point = ρ for both.
            let (d11, d12, d22) = (dot(n1, n1), dot(n1, n2), dot(n2, n2));
            let det = d11 * d22 - d12 * d12;
            let a = (r1 * d22 - r2 * d12) / det;
            let b = (r2 * d11 - r1 * d12) / det;
            let origin = [0, 1, 2].map(|k| a * n1[k] + b * n2[k]);
            let (mut t_min, mut t_max) = (f32::INFINITY, f32::NEG_INFINITY);
            for c in colors {
                let c = unit(c);
                let t = dot([0, 1, 2].map(|k| c[k] - origin[k]), dir) / dir_len2;
                t_min = t_min.min(t);
                t_max = t_max.max(t);
            }
            let at = |t: f32| [0, 1, 2].map(|k| (origin[k] + t * dir[k]) * 255.0);
            return [at(t_min), at(t_max)];
        }
        // Every pair degenerate: the colours barely vary; span their first and last.
        let ends = |c: &[u8; 3]| c.map(f32::from);
        [ends(&colors[0]), ends(&colors[colors.len() - 1])]
    }
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attr::pack_rgb;

    #[test]
    fn a_gradient_becomes_one_block_and_noise_stays_within_threshold() {
        let gradient: Vec<u32> = (0..200u32)
            .map(|i| pack_rgb([i as u8, (255 - i) as u8, (i / 2) as u8]))
            .collect();
        let blocks = encode_blocks(&gradient, DEFAULT_THRESHOLD);
        assert!(
            blocks.len() <= 2,
            "{} blocks for a straight gradient",
            blocks.len()
        );
        let words = encode(&gradient, DEFAULT_THRESHOLD);
        let decoded = varbit::decode_all(&words, gradient.len()).unwrap();
        for (a, b) in gradient.iter().zip(&decoded) {
            assert!(varbit::channel_error(rgb(*a), rgb(*b)) <= 15);
        }
    }
}
