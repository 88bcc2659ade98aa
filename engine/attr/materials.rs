//! Materials: a palette of at most 16 sRGB colours and one 4-bit palette index per voxel, in the
//! depth-first Morton voxel order of `Svdag::colors` (`docs/materials.md`).
//!
//! `voxdag build --materials K` makes them from the imported colours with [`Materials::quantize`]:
//! the exact colours when the scene uses at most `K`, else k-means in linear RGB (k-means++
//! seeding from a fixed seed, a bounded number of Lloyd iterations, on a deterministic sample
//! of the distinct colours when there are many). The hash DAG stores the ids in its leaves
//! (`edit::item`), the `.vdag` file in its material section (`docs/vdag-format.md`).

use rustc_hash::FxHashMap;

use super::AttrError;
use crate::color::{linear_to_srgb, srgb_to_linear};

/// Most palette entries (ids are 4 bits).
pub const MAX_MATERIALS: u32 = 16;
/// Seed of the k-means++ seeding (fixed: the same colours always give the same palette).
pub const KMEANS_SEED: u64 = 0x6d61_7465_7269_616c;
/// Most Lloyd iterations after seeding.
pub const KMEANS_ITERATIONS: u32 = 32;
/// Most distinct colours k-means runs on; more are sampled down to this many.
pub const KMEANS_SAMPLE: usize = 1 << 16;

/// A palette and one palette index per voxel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Materials {
    /// RGBA8 sRGB colours (`r | g << 8 | b << 16 | a << 24`), `1..=16` entries.
    pub palette: Vec<u32>,
    /// One id (`< palette.len()`) per voxel, depth-first Morton order.
    pub ids: Vec<u8>,
}

/// splitmix64, the seeding's random numbers.
struct SplitMix(u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut x = self.0;
        x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        x ^ (x >> 31)
    }

    /// Uniform in `[0, 1)`.
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Linear RGB of an RGBA8 word.
fn linear(color: u32, lut: &[f32; 256]) -> [f32; 3] {
    [
        lut[(color & 0xff) as usize],
        lut[(color >> 8 & 0xff) as usize],
        lut[(color >> 16 & 0xff) as usize],
    ]
}

fn distance2(a: [f32; 3], b: [f32; 3]) -> f32 {
    (0..3).map(|i| (a[i] - b[i]) * (a[i] - b[i])).sum()
}

/// Index of the nearest centre (the lowest index on ties).
fn nearest(p: [f32; 3], centres: &[[f32; 3]]) -> usize {
    let mut best = (0, f32::INFINITY);
    for (i, c) in centres.iter().enumerate() {
        let d = distance2(p, *c);
        if d < best.1 {
            best = (i, d);
        }
    }
    best.0
}

/// The opaque RGBA8 word of a linear colour.
fn to_srgb8(c: [f32; 3]) -> u32 {
    let ch = |v: f32| (linear_to_srgb(v) * 255.0).round() as u32;
    ch(c[0]) | ch(c[1]) << 8 | ch(c[2]) << 16 | 0xff00_0000
}

/// Weighted k-means of `points` (linear RGB, weight) into at most `k` centres.
fn kmeans(points: &[([f32; 3], u64)], k: usize) -> Vec<[f32; 3]> {
    let mut rng = SplitMix(KMEANS_SEED);
    let total: f64 = points.iter().map(|p| p.1 as f64).sum();
    // k-means++: the first centre by weight, then each with probability ~ weight * D^2.
    let mut pick = rng.unit() * total;
    let first = points
        .iter()
        .position(|p| {
            pick -= p.1 as f64;
            pick < 0.0
        })
        .unwrap_or(points.len() - 1);
    let mut centres = vec![points[first].0];
    let mut d2: Vec<f64> = points
        .iter()
        .map(|p| distance2(p.0, centres[0]) as f64 * p.1 as f64)
        .collect();
    while centres.len() < k {
        let sum: f64 = d2.iter().sum();
        if sum <= 0.0 {
            break; // every point is a centre already
        }
        let mut pick = rng.unit() * sum;
        let next = d2
            .iter()
            .position(|&d| {
                pick -= d;
                pick < 0.0 && d > 0.0
            })
            .unwrap_or_else(|| d2.iter().rposition(|&d| d > 0.0).expect("sum > 0"));
        let c = points[next].0;
        centres.push(c);
        for (d, p) in d2.iter_mut().zip(points) {
            *d = d.min(distance2(p.0, c) as f64 * p.1 as f64);
        }
    }
    // Lloyd iterations; an empty cluster keeps its centre.
    let mut assignment = vec![usize::MAX; points.len()];
    for _ in 0..KMEANS_ITERATIONS {
        let mut changed = false;
        for (a, p) in assignment.iter_mut().zip(points) {
            let n = nearest(p.0, &centres);
            changed |= *a != n;
            *a = n;
        }
        if !changed {
            break;
        }
        let mut sums = vec![([0f64; 3], 0f64); centres.len()];
        for (&a, p) in assignment.iter().zip(points) {
            for i in 0..3 {
                sums[a].0[i] += p.0[i] as f64 * p.1 as f64;
            }
            sums[a].1 += p.1 as f64;
        }
        for (c, (s, w)) in centres.iter_mut().zip(sums) {
            if w > 0.0 {
                *c = s.map(|v| (v / w) as f32);
            }
        }
    }
    centres
}

impl Materials {
    /// Materials from a palette and ids, checked ([`Materials::validate`]).
    pub fn new(palette: Vec<u32>, ids: Vec<u8>) -> Result<Materials, AttrError> {
        let m = Materials { palette, ids };
        m.validate()?;
        Ok(m)
    }

    /// Checks `1..=16` palette entries and every id below the palette size.
    pub fn validate(&self) -> Result<(), AttrError> {
        let n = self.palette.len();
        if !(1..=MAX_MATERIALS as usize).contains(&n) {
            return Err(AttrError::Invalid(format!(
                "palette of {n} entries (1..=16)"
            )));
        }
        if let Some(i) = self.ids.iter().position(|&id| id as usize >= n) {
            return Err(AttrError::Invalid(format!(
                "voxel {i} has material {} of a {n}-entry palette",
                self.ids[i]
            )));
        }
        Ok(())
    }

    /// Quantizes per-voxel RGBA8 colours into a palette of at most `k` (`1..=16`) colours and
    /// gives each voxel the nearest entry (linear RGB distance; alpha is not kept: palette
    /// entries are opaque, as every colour codec's output is).
    ///
    /// When the colours hold at most `k` distinct RGB values the palette is exactly those values
    /// (ascending `r | g << 8 | b << 16`), so a `.vox` model with at most `k` palette colours
    /// keeps them. Otherwise: weighted k-means on the distinct colours in linear RGB (weight =
    /// voxels of that colour; every `ceil(d / 65536)`-th of the `d` distinct colours in
    /// ascending order when `d > 65536`), k-means++ seeding with splitmix64 from
    /// [`KMEANS_SEED`], at most [`KMEANS_ITERATIONS`] Lloyd iterations (stopping when no
    /// assignment changes); the centres are rounded to sRGB8, duplicates removed and sorted
    /// ascending. Deterministic: the same colours always give the same result. Colourless
    /// scenes (`colors` empty) get a one-entry white palette.
    pub fn quantize(colors: &[u32], k: u32) -> Result<Materials, AttrError> {
        if !(1..=MAX_MATERIALS).contains(&k) {
            return Err(AttrError::Invalid(format!(
                "{k} materials asked for (1..=16)"
            )));
        }
        let mut histogram: FxHashMap<u32, u64> = FxHashMap::default();
        for &c in colors {
            *histogram.entry(c & 0x00ff_ffff).or_default() += 1;
        }
        let mut distinct: Vec<(u32, u64)> = histogram.into_iter().collect();
        distinct.sort_unstable();
        if distinct.len() <= k as usize {
            let palette: Vec<u32> = if distinct.is_empty() {
                vec![0xffff_ffff]
            } else {
                distinct.iter().map(|&(c, _)| c | 0xff00_0000).collect()
            };
            let index: FxHashMap<u32, u8> = distinct
                .iter()
                .enumerate()
                .map(|(i, &(c, _))| (c, i as u8))
                .collect();
            let ids = colors.iter().map(|c| index[&(c & 0x00ff_ffff)]).collect();
            return Materials::new(palette, ids);
        }
        let lut: [f32; 256] = std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0));
        let stride = distinct.len().div_ceil(KMEANS_SAMPLE);
        let points: Vec<([f32; 3], u64)> = distinct
            .iter()
            .step_by(stride)
            .map(|&(c, n)| (linear(c, &lut), n))
            .collect();
        let mut palette: Vec<u32> = kmeans(&points, k as usize)
            .into_iter()
            .map(to_srgb8)
            .collect();
        palette.sort_unstable();
        palette.dedup();
        let centres: Vec<[f32; 3]> = palette.iter().map(|&c| linear(c, &lut)).collect();
        let index: FxHashMap<u32, u8> = distinct
            .iter()
            .map(|&(c, _)| (c, nearest(linear(c, &lut), &centres) as u8))
            .collect();
        let ids = colors.iter().map(|c| index[&(c & 0x00ff_ffff)]).collect();
        Materials::new(palette, ids)
    }

    /// The colour of every voxel (`palette[id]`), for renderers that take colours.
    pub fn to_colors(&self) -> Vec<u32> {
        self.ids
            .iter()
            .map(|&id| self.palette[id as usize])
            .collect()
    }

    /// The palette as 16 entries; entries past the palette are zero.
    pub fn palette16(&self) -> [u32; 16] {
        std::array::from_fn(|i| self.palette.get(i).copied().unwrap_or(0))
    }

    /// The ids two per byte, voxel `2i` in the low nibble of byte `i` (a last odd voxel leaves
    /// the high nibble zero).
    pub fn packed_ids(&self) -> Vec<u8> {
        self.ids
            .chunks(2)
            .map(|p| p[0] | p.get(1).map_or(0, |h| h << 4))
            .collect()
    }

    /// Unpacks `count` ids from [`Materials::packed_ids`] bytes (`bytes.len()` must be
    /// `ceil(count / 2)`); `Err(byte index)` when the unused high nibble of an odd count is set.
    pub fn unpack_ids(bytes: &[u8], count: usize) -> Result<Vec<u8>, usize> {
        debug_assert_eq!(bytes.len(), count.div_ceil(2));
        let mut ids = Vec::with_capacity(count);
        for &b in bytes {
            ids.push(b & 15);
            ids.push(b >> 4);
        }
        if ids.len() > count {
            if ids[count] != 0 {
                return Err(bytes.len() - 1);
            }
            ids.truncate(count);
        }
        Ok(ids)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn few_colours_are_kept_exactly() {
        let colors = [0xff00_00ffu32, 0xff00_ff00, 0xff00_00ff, 0x80ff_0000];
        let m = Materials::quantize(&colors, 3).unwrap();
        assert_eq!(m.palette, vec![0xff00_00ff, 0xff00_ff00, 0xffff_0000]);
        assert_eq!(m.ids, vec![0, 1, 0, 2]);
        assert_eq!(m.to_colors()[..3], [0xff00_00ff, 0xff00_ff00, 0xff00_00ff]);
    }

    #[test]
    fn kmeans_is_bounded_and_deterministic() {
        let colors: Vec<u32> = (0..5000u32)
            .map(|i| (i * 2_654_435_761u32) & 0x00ff_ffff | 0xff00_0000)
            .collect();
        let a = Materials::quantize(&colors, 7).unwrap();
        let b = Materials::quantize(&colors, 7).unwrap();
        assert_eq!(a, b);
        assert!(a.palette.len() <= 7 && a.palette.len() >= 2);
        assert_eq!(a.ids.len(), colors.len());
        a.validate().unwrap();
    }

    #[test]
    fn packing_round_trips_and_checks_padding() {
        let m = Materials::new(vec![1, 2, 3], vec![2, 1, 0, 2, 1]).unwrap();
        let packed = m.packed_ids();
        assert_eq!(packed, vec![0x12, 0x20, 0x01]);
        assert_eq!(Materials::unpack_ids(&packed, 5).unwrap(), m.ids);
        assert_eq!(Materials::unpack_ids(&[0x12, 0x20, 0x11], 5), Err(2));
        assert!(Materials::new(vec![], vec![]).is_err());
        assert!(Materials::new(vec![1], vec![1]).is_err());
    }
}
