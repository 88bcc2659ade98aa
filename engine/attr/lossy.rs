//! The real-time lossy colour encoder (dissertation §5.2.2): one greedy pass over the colour
//! stream that fits line segments with the continuous Hough transform, written in the Dolonius et
//! al. variable-bitrate format (`varbit`).
//!
//! A segment grows one colour at a time, up to [`MAX_SEGMENT`] colours. Each of the three planes
//! RG, GB and RB keeps, for [`THETA_STEPS`] line angles θ, the range [ρmin, ρmax] of
//! `ρ = x cos θ + y sin θ` over the segment's colours (channels in [0, 1]); an angle is dropped
//! once ρmax - ρmin exceeds twice the Hough band (no line at that angle passes within the band of
//! every colour). The segment ends before the colour that would leave some plane without angles.
//! The 3D line is rebuilt from the two planes whose colours spread widest (the intersection of
//! their best lines, each a plane in RGB space), and clipped to the colours' projections.
//! `varbit::endpoint_block` then picks the fewest bits (1-4) whose decoded colours, after RGB565
//! endpoint quantization, all stay within the threshold; a segment that fails even with 4 bits is
//! cut before its first failing colour (or halved) and refitted.
//!
//! The block emitted is the one with the lowest rate-distortion cost per colour (64 header bits +
//! weights + `ERROR_WEIGHT` × squared error) of: the longest run one single colour holds, the
//! longest within half the threshold, the Hough segment and the segment refitted by least squares,
//! each at the fewest bits that hold it and one more, and the segment's prefixes that its
//! line (clipped to the prefix) holds with fewer bits. Every candidate keeps the threshold; the
//! cost spends the size budget on lowering the error. A single run that no endpoint block could
//! beat skips the Hough pass. Macro blocks are encoded in parallel.

use rayon::prelude::*;

use super::rgb;
use super::varbit::{self, BlockColors, VarbitBlock, MACRO_BLOCK_COLORS};

/// The default per-channel error threshold (colours in [0, 1]).
pub const DEFAULT_THRESHOLD: f32 = 0.06;
/// Number of line angles θ per plane, evenly spaced over [0, π).
pub const THETA_STEPS: usize = 64;
/// Longest segment, in colours: the greedy choice of a block is revisited at least this often,
/// so that a long line segment does not swallow runs that cheaper blocks would hold.
pub const MAX_SEGMENT: usize = 256;
/// Half-width of the Hough band as a fraction of the threshold: the rest of the threshold is left
/// to the weight quantization along the line.
const BAND_FRACTION: f32 = 0.5;
/// Bits a block may spend to remove one unit of squared error (8-bit steps, summed over
/// channels): the exchange rate between size and error when choosing among blocks.
const ERROR_WEIGHT: f64 = 0.04;
/// Power iterations for the principal axis of a segment's colours.
const POWER_ITERATIONS: usize = 8;

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
        let end = colors.len().min(i + MAX_SEGMENT);
        let (len, block) = next_block(&colors[i..end], offset + i, &mut hough, max_delta);
        blocks.push(block);
        i += len;
    }
    blocks
}

/// The block at the start of `colors` and its length: of the longest single-colour run, a
/// shorter run held within half the threshold, the Hough segment with its Hough and its
/// least-squares line at every width that holds it, and the segment's prefixes that its line
/// holds with fewer bits, the one with the lowest rate-distortion cost per colour.
fn next_block(
    colors: &[[u8; 3]],
    start: usize,
    hough: &mut Hough,
    max_delta: u8,
) -> (usize, VarbitBlock) {
    let run = single_run(colors, max_delta);
    let single = varbit::single_block(&colors[..run], start, max_delta)
        .expect("single_run checked the block");
    let mut best = Candidate::new(colors, run, single);
    // No endpoint block (1 bit per weight and no error at best) can beat a cheap enough run.
    if best.cost <= (64 + colors.len()) as f64 / colors.len() as f64 {
        return best.into_block();
    }
    let tight = single_run(colors, max_delta / 2);
    if let Some(block) = varbit::single_block(&colors[..tight], start, max_delta / 2) {
        best = best.min(Candidate::new(colors, tight, block));
    }
    let mut limit = colors.len();
    let (len, line, block) = loop {
        let end = hough.segment(&colors[..limit]);
        let line = hough.line(&colors[..end]);
        match varbit::endpoint_block(&colors[..end], start, line, 1..=4, max_delta) {
            Ok(block) => break (end, line, block),
            // A segment no line holds ends before its first failing colour; the first colour
            // failing means the line is poor: halve the segment.
            Err(0) if end <= 1 => return best.into_block(),
            Err(0) => limit = end / 2,
            Err(fail) => limit = fail,
        }
    };
    let fewest_bits = block.bits;
    best = best.min(Candidate::new(colors, len, block));
    // One bit more than the fewest that hold the segment, and the least-squares line at its
    // fewest bits and one more, trade size for error; the cost decides.
    let segment = &colors[..len];
    let one_more = |bits: u8| (bits < 4).then_some(bits + 1);
    let mut refits = vec![(line, one_more(fewest_bits))];
    let refit = least_squares_line(segment);
    if let Ok(block) = varbit::endpoint_block(segment, start, refit, 1..=4, max_delta) {
        refits.push((refit, one_more(block.bits)));
        best = best.min(Candidate::new(colors, len, block));
    }
    for (line, bits) in refits {
        let Some(bits) = bits else { continue };
        if let Ok(block) = varbit::endpoint_block(segment, start, line, bits..=bits, max_delta) {
            best = best.min(Candidate::new(colors, len, block));
        }
    }
    // Shorter prefixes on the same line, clipped to their own colours, may need fewer bits.
    for bits in 1..fewest_bits {
        let prefix = varbit::longest_prefix(len, |p| {
            let clipped = clip(line, &colors[..p]);
            varbit::endpoint_block(&colors[..p], start, clipped, bits..=bits, max_delta).ok()
        });
        if let Some((p, block)) = prefix {
            best = best.min(Candidate::new(colors, p, block));
        }
    }
    best.into_block()
}

/// A block for the first `len` colours and its rate-distortion cost per colour: stored bits
/// (64 header bits + weights) plus [`ERROR_WEIGHT`] times the squared error (8-bit steps, summed
/// over channels).
struct Candidate {
    len: usize,
    block: VarbitBlock,
    cost: f64,
}

impl Candidate {
    fn new(colors: &[[u8; 3]], len: usize, block: VarbitBlock) -> Candidate {
        let bits = 64 + usize::from(block.bits) * len;
        let error = squared_error(&colors[..len], &block);
        let cost = (bits as f64 + ERROR_WEIGHT * error as f64) / len as f64;
        Candidate { len, block, cost }
    }

    /// The cheaper of two candidates, `self` on a tie.
    fn min(self, other: Candidate) -> Candidate {
        if other.cost < self.cost {
            other
        } else {
            self
        }
    }

    fn into_block(self) -> (usize, VarbitBlock) {
        (self.len, self.block)
    }
}

/// Sum over `colors` and channels of the squared difference (8-bit steps) to what the decoder
/// returns for `block`.
fn squared_error(colors: &[[u8; 3]], block: &VarbitBlock) -> u64 {
    let squared = |c: &[u8; 3], d: [u8; 3]| -> u64 {
        (0..3).map(|k| u64::from(c[k].abs_diff(d[k])).pow(2)).sum()
    };
    match block.kind {
        BlockColors::Single(word) => {
            let decoded = varbit::expand101210(word);
            colors.iter().map(|c| squared(c, decoded)).sum()
        }
        BlockColors::Endpoints { a565, b565 } => {
            let (a8, b8) = (varbit::expand565(a565), varbit::expand565(b565));
            let bits = u32::from(block.bits);
            colors
                .iter()
                .zip(&block.weights)
                .map(|(c, &w)| squared(c, varbit::blend(a8, b8, u32::from(w), bits)))
                .sum()
        }
    }
}

/// The least-squares line through `colors` (endpoints, channels in [0, 255]): through their mean
/// along the principal axis of their covariance, clipped to their projections.
fn least_squares_line(colors: &[[u8; 3]]) -> [[f32; 3]; 2] {
    let n = colors.len() as f32;
    let mut mean = [0.0f32; 3];
    for c in colors {
        for k in 0..3 {
            mean[k] += f32::from(c[k]) / n;
        }
    }
    let mut cov = [[0.0f32; 3]; 3];
    for c in colors {
        let d = [0, 1, 2].map(|k| f32::from(c[k]) - mean[k]);
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] += d[i] * d[j];
            }
        }
    }
    // Power iteration from the widest channel's axis, which is never orthogonal to the principal
    // axis unless the covariance is degenerate.
    let widest = (0..3)
        .max_by(|&i, &j| cov[i][i].total_cmp(&cov[j][j]))
        .unwrap_or(0);
    let mut axis = [0.0f32; 3];
    axis[widest] = 1.0;
    for _ in 0..POWER_ITERATIONS {
        let next = [0, 1, 2].map(|i| dot(cov[i], axis));
        let len = dot(next, next).sqrt();
        if len <= f32::EPSILON {
            break;
        }
        axis = next.map(|v| v / len);
    }
    let end = [0, 1, 2].map(|k| mean[k] + axis[k]);
    clip([mean, end], colors)
}

/// The part of `line` (endpoints, channels in [0, 255]) between the projections of `colors`.
fn clip([a, b]: [[f32; 3]; 2], colors: &[[u8; 3]]) -> [[f32; 3]; 2] {
    let dir = [0, 1, 2].map(|k| b[k] - a[k]);
    let len2 = dot(dir, dir);
    if len2 <= 0.0 {
        return [a, b];
    }
    let (mut t_min, mut t_max) = (f32::INFINITY, f32::NEG_INFINITY);
    for c in colors {
        let t = dot([0, 1, 2].map(|k| f32::from(c[k]) - a[k]), dir) / len2;
        t_min = t_min.min(t);
        t_max = t_max.max(t);
    }
    let at = |t: f32| [0, 1, 2].map(|k| a[k] + t * dir[k]);
    [at(t_min), at(t_max)]
}

/// Length of the longest prefix of `colors` (at least 1) that one single-colour block holds.
fn single_run(colors: &[[u8; 3]], max_delta: u8) -> usize {
    let (mut lo, mut hi) = (colors[0], colors[0]);
    let mut run = colors.len();
    for (n, c) in colors.iter().enumerate() {
        for k in 0..3 {
            lo[k] = lo[k].min(c[k]);
            hi[k] = hi[k].max(c[k]);
        }
        if (0..3).any(|k| hi[k] - lo[k] > max_delta.saturating_mul(2)) {
            run = n;
            break;
        }
    }
    // The block's colour is the range's centre rounded to 10-12-10: shrink in the rare case the
    // rounding breaks the bound.
    while run > 1 && varbit::single_block(&colors[..run], 0, max_delta).is_none() {
        run -= 1;
    }
    run
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
    fn a_flat_run_is_one_single_block_and_a_ramp_few_blocks() {
        let flat: Vec<u32> = (0..200u32)
            .map(|i| pack_rgb([100 + (i % 7) as u8, 50, 20]))
            .collect();
        let blocks = encode_blocks(&flat, DEFAULT_THRESHOLD);
        assert_eq!(blocks.len(), 1);
        assert_eq!(blocks[0].bits, 0);
        // A straight ramp: each block covers many colours.
        let gradient: Vec<u32> = (0..200u32)
            .map(|i| pack_rgb([i as u8, (255 - i) as u8, (i / 2) as u8]))
            .collect();
        let blocks = encode_blocks(&gradient, DEFAULT_THRESHOLD);
        assert!(blocks.len() <= 8, "{} blocks for a ramp", blocks.len());
        let words = encode(&gradient, DEFAULT_THRESHOLD);
        let decoded = varbit::decode_all(&words, gradient.len()).unwrap();
        for (a, b) in gradient.iter().zip(&decoded) {
            assert!(varbit::channel_error(rgb(*a), rgb(*b)) <= 15);
        }
    }

    #[test]
    fn segments_never_exceed_max_segment() {
        let grey: Vec<u32> = (0..5000u32)
            .map(|i| pack_rgb([(i * 37 % 256) as u8; 3]))
            .collect();
        let blocks = encode_blocks(&grey, DEFAULT_THRESHOLD);
        for (j, b) in blocks.iter().enumerate() {
            let end = blocks.get(j + 1).map_or(grey.len(), |n| n.start);
            assert!(end - b.start <= MAX_SEGMENT);
        }
    }

    #[test]
    fn least_squares_line_spans_a_ramp_and_squared_error_matches_the_decoder() {
        let ramp: Vec<[u8; 3]> = (0..100u8).map(|i| [i * 2, 200 - i, 50 + i / 2]).collect();
        let [a, b] = least_squares_line(&ramp);
        let (first, last) = (ramp[0].map(f32::from), ramp[99].map(f32::from));
        let near = |p: [f32; 3], q: [f32; 3]| (0..3).all(|k| (p[k] - q[k]).abs() < 0.5);
        assert!(
            (near(a, first) && near(b, last)) || (near(a, last) && near(b, first)),
            "{a:?} {b:?}"
        );
        // The error the block choice weighs is the decoder's.
        let colors: Vec<u32> = (0..3000u32)
            .map(|i| pack_rgb([(i * 7 % 251) as u8, (i / 13) as u8, (i * i % 97) as u8]))
            .collect();
        let blocks = encode_blocks(&colors, DEFAULT_THRESHOLD);
        let decoded =
            varbit::decode_all(&encode(&colors, DEFAULT_THRESHOLD), colors.len()).unwrap();
        let expected: u64 = colors
            .iter()
            .zip(&decoded)
            .map(|(&c, &d)| {
                let (c, d) = (rgb(c), rgb(d));
                (0..3)
                    .map(|k| u64::from(c[k].abs_diff(d[k])).pow(2))
                    .sum::<u64>()
            })
            .sum();
        let rgb8: Vec<[u8; 3]> = colors.iter().map(|&c| rgb(c)).collect();
        let weighed: u64 = blocks
            .iter()
            .enumerate()
            .map(|(j, b)| {
                let end = blocks.get(j + 1).map_or(colors.len(), |n| n.start);
                squared_error(&rgb8[b.start..end], b)
            })
            .sum();
        assert_eq!(weighed, expected);
    }
}
