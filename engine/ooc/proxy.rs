//! SVDAG proxies of the batching points: one shared multi-root SVDAG (nodes deduplicated across
//! points), the conservative voxelization that feeds it, the any-hit ray/segment test and its
//! file `proxies-R.bin`.
//!
//! Each point's proxy is a `R^3` grid over the cube at its bounds' minimum corner whose side is
//! the bounds' largest extent. A voxel is set when the closed triangle overlaps the closed voxel
//! ([`crate::scene::voxelize::tri_box_overlap`], the voxelizer's test), so the union of a point's
//! voxels contains all its triangles. The words use the `svdag32` layout of `crate::dag`; the
//! roots are word offsets into the same array.

use std::io::Write;
use std::path::Path;

use rustc_hash::FxHashMap;

use super::geom::{Aabb, Tri};
use super::OocError;
use crate::dag::Svdag;
use crate::scene::morton;
use crate::scene::voxelize::{tri_box_overlap, GridTriangle};
use crate::scene::Voxels;

/// Magic bytes of a proxy file.
pub const PROXY_MAGIC: &[u8; 8] = b"VXOOCPRX";
/// Version of the proxy file format.
pub const PROXY_VERSION: u32 = 1;

/// The affine map from world space to a point's proxy grid: `g = (p - lo) * scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// World position of grid corner (0, 0, 0).
    pub lo: [f64; 3],
    /// Grid cells per world unit.
    pub scale: f64,
    /// Slack added to every voxel box in the ray test, in cells: covers the f32 rounding of the
    /// triangle test (a few ulps of the coordinates) with room to spare.
    pub slack: f64,
    /// Grid side in cells.
    pub resolution: u32,
}

impl Grid {
    /// The grid of a point with bounds `b` at `resolution` cells per side.
    pub fn new(b: &Aabb, resolution: u32) -> Grid {
        let ext = (0..3)
            .map(|k| (b.hi[k] - b.lo[k]) as f64)
            .fold(0.0, f64::max);
        let side = if ext > 0.0 { ext } else { 1.0 };
        let scale = resolution as f64 / side;
        let coord = (0..3)
            .map(|k| (b.lo[k].abs()).max(b.hi[k].abs()) as f64)
            .fold(0.0, f64::max);
        Grid {
            lo: b.lo.map(|v| v as f64),
            scale,
            slack: 0.01 + 64.0 * f32::EPSILON as f64 * (coord + side) * scale,
            resolution,
        }
    }

    /// A world point in grid coordinates.
    pub fn to_grid(&self, p: [f32; 3]) -> [f64; 3] {
        [0, 1, 2].map(|k| (p[k] as f64 - self.lo[k]) * self.scale)
    }

    /// The cell holding grid point `g` (clamped into the grid).
    pub fn cell(&self, g: [f64; 3]) -> [u32; 3] {
        g.map(|v| (v.floor().max(0.0) as u32).min(self.resolution - 1))
    }

    /// A triangle in grid coordinates for the overlap test.
    pub fn triangle(&self, t: &Tri) -> GridTriangle {
        GridTriangle::new([self.to_grid(t[0]), self.to_grid(t[1]), self.to_grid(t[2])])
    }

    /// Calls `f` with every cell the closed triangle overlaps.
    pub fn for_overlapped(&self, t: &Tri, mut f: impl FnMut([u32; 3])) {
        let g = [self.to_grid(t[0]), self.to_grid(t[1]), self.to_grid(t[2])];
        let mut lo = [u32::MAX; 3];
        let mut hi = [0u32; 3];
        for v in g {
            let c = self.cell(v);
            for k in 0..3 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
        if lo == hi {
            // The triangle lies in this one cell: no separating-axis test needed (most
            // triangles of the scanned meshes are smaller than a proxy voxel).
            f(lo);
            return;
        }
        let gt = GridTriangle::new(g);
        for z in lo[2]..=hi[2] {
            for y in lo[1]..=hi[1] {
                for x in lo[0]..=hi[0] {
                    if tri_box_overlap(&gt, [x, y, z]) {
                        f([x, y, z]);
                    }
                }
            }
        }
    }
}

/// Conservative voxelization of a point's triangles in its grid.
pub fn voxelize_point(tris: &[Tri], grid: &Grid) -> Voxels {
    let mut coords: Vec<[u32; 3]> = Vec::new();
    for t in tris {
        // Neighbouring triangles (Morton order) often share a cell: skip repeats at once.
        grid.for_overlapped(t, |c| {
            if coords.last() != Some(&c) {
                coords.push(c)
            }
        });
    }
    Voxels::from_coords(grid.resolution, coords)
}

/// The proxies of all points: one multi-root SVDAG.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProxySet {
    /// Grid side of every proxy.
    pub resolution: u32,
    /// Nodes in the `svdag32` layout, levels top-down.
    pub words: Vec<u32>,
    /// `level_starts[l]` = first word of level `l` (0 = leaves).
    pub level_starts: Vec<u32>,
    /// Root word offset of each point's proxy.
    pub roots: Vec<u32>,
}

/// One level of the shared node pool while proxies are added.
#[derive(Default)]
struct PoolLevel {
    /// Node words, children as ids into the level below.
    words: Vec<u32>,
    /// Word offset of each node in `words`.
    offsets: Vec<u32>,
    /// Node content -> id.
    ids: FxHashMap<Vec<u32>, u32>,
}

impl PoolLevel {
    fn intern(&mut self, node: Vec<u32>) -> u32 {
        if let Some(&id) = self.ids.get(&node) {
            return id;
        }
        let id = self.offsets.len() as u32;
        self.offsets.push(self.words.len() as u32);
        self.words.extend_from_slice(&node);
        self.ids.insert(node, id);
        id
    }
}

/// Builds a [`ProxySet`] from per-point SVDAGs, deduplicating nodes across points.
pub struct ProxyBuilder {
    resolution: u32,
    levels: Vec<PoolLevel>,
    roots: Vec<u32>,
}

impl ProxyBuilder {
    /// An empty pool for proxies of side `resolution` (a power of two, 8..=4096).
    pub fn new(resolution: u32) -> ProxyBuilder {
        let levels = (0..resolution.trailing_zeros() - 1)
            .map(|_| PoolLevel::default())
            .collect();
        ProxyBuilder {
            resolution,
            levels,
            roots: Vec::new(),
        }
    }

    /// Adds the next point's proxy (a DAG of this pool's resolution).
    pub fn add(&mut self, dag: &Svdag) {
        debug_assert_eq!(dag.resolution, self.resolution);
        let root_level = self.levels.len() - 1;
        // Local word offset -> pool id, for the level below the one being added.
        let mut below: FxHashMap<u32, u32> = FxHashMap::default();
        for l in 0..=root_level {
            let start = dag.level_starts[l] as usize;
            let end = if l == 0 {
                dag.words.len()
            } else {
                dag.level_starts[l - 1] as usize
            };
            let mut here: FxHashMap<u32, u32> = FxHashMap::default();
            let mut p = start;
            while p < end {
                let node = if l == 0 {
                    dag.words[p..p + 2].to_vec()
                } else {
                    let mask = dag.words[p];
                    let n = mask.count_ones() as usize;
                    let mut node = Vec::with_capacity(n + 1);
                    node.push(mask);
                    node.extend(dag.words[p + 1..p + 1 + n].iter().map(|c| below[c]));
                    node
                };
                let len = node.len();
                here.insert(p as u32, self.levels[l].intern(node));
                p += len;
            }
            below = here;
        }
        self.roots.push(below[&0]);
    }

    /// Lays the pool out top-down with absolute child offsets.
    pub fn finish(self) -> ProxySet {
        let n = self.levels.len();
        let mut level_starts = vec![0u32; n];
        let mut total = 0u32;
        for l in (0..n).rev() {
            level_starts[l] = total;
            total += self.levels[l].words.len() as u32;
        }
        let mut words = Vec::with_capacity(total as usize);
        for l in (0..n).rev() {
            let level = &self.levels[l];
            if l == 0 {
                words.extend_from_slice(&level.words);
                continue;
            }
            let below = &self.levels[l - 1];
            let base = level_starts[l - 1];
            for &off in &level.offsets {
                let mask = level.words[off as usize];
                words.push(mask);
                let kids =
                    &level.words[off as usize + 1..off as usize + 1 + mask.count_ones() as usize];
                words.extend(kids.iter().map(|&c| base + below.offsets[c as usize]));
            }
        }
        let top = &self.levels[n - 1];
        let roots = self
            .roots
            .iter()
            .map(|&r| level_starts[n - 1] + top.offsets[r as usize])
            .collect();
        ProxySet {
            resolution: self.resolution,
            words,
            level_starts,
            roots,
        }
    }
}

/// Segment/box test in f64 on the closed box `[lo, hi]`.
#[inline]
fn segment_box(o: [f64; 3], d: [f64; 3], lo: [f64; 3], hi: [f64; 3], t0: f64, t1: f64) -> bool {
    let (mut t0, mut t1) = (t0, t1);
    for k in 0..3 {
        if d[k] == 0.0 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return false;
            }
            continue;
        }
        let inv = 1.0 / d[k];
        let a = (lo[k] - o[k]) * inv;
        let b = (hi[k] - o[k]) * inv;
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    t0 <= t1
}

impl ProxySet {
    /// Bytes the proxies take in memory (words and roots).
    pub fn bytes(&self) -> u64 {
        4 * (self.words.len() + self.roots.len() + self.level_starts.len()) as u64
    }

    /// True when the ray `origin + t dir`, `t` in `[t0, t1]` (world space), may touch a voxel of
    /// point `point`'s proxy: every voxel box is widened by the grid's slack and the segment by
    /// a relative margin, so a hit the f32 triangle test can report is never culled.
    pub fn segment_hits(
        &self,
        point: u32,
        grid: &Grid,
        origin: [f32; 3],
        dir: [f32; 3],
        t0: f32,
        t1: f32,
    ) -> bool {
        let o = grid.to_grid(origin);
        let d = dir.map(|v| v as f64 * grid.scale);
        let margin = 1e-4 * (t0.abs().max(t1.abs()) as f64) + 1e-30;
        let (t0, t1) = (t0 as f64 - margin, t1 as f64 + margin);
        let eps = grid.slack;
        let root_level = self.level_starts.len() as u32 - 1;
        let mut stack: Vec<(u32, u32, [u32; 3])> = Vec::with_capacity(64);
        stack.push((self.roots[point as usize], root_level, [0; 3]));
        while let Some((node, level, pos)) = stack.pop() {
            if level == 0 {
                let mask =
                    self.words[node as usize] as u64 | (self.words[node as usize + 1] as u64) << 32;
                let mut m = mask;
                while m != 0 {
                    let bit = m.trailing_zeros() as u64;
                    m &= m - 1;
                    let v = morton::decode(bit);
                    let lo = [0, 1, 2].map(|k| (pos[k] + v[k]) as f64 - eps);
                    let hi = [0, 1, 2].map(|k| (pos[k] + v[k] + 1) as f64 + eps);
                    if segment_box(o, d, lo, hi, t0, t1) {
                        return true;
                    }
                }
                continue;
            }
            let half = 2u32 << level;
            let mask = self.words[node as usize] & 0xff;
            let mut rank = 0;
            for c in 0..8u32 {
                if mask & (1 << c) == 0 {
                    continue;
                }
                let child = self.words[(node + 1 + rank) as usize];
                rank += 1;
                let cp = [0, 1, 2].map(|k| pos[k] + ((c >> k) & 1) * half);
                let lo = cp.map(|v| v as f64 - eps);
                let hi = cp.map(|v| (v + half) as f64 + eps);
                if segment_box(o, d, lo, hi, t0, t1) {
                    stack.push((child, level - 1, cp));
                }
            }
        }
        false
    }

    /// True when voxel `v` of point `point`'s proxy is set.
    pub fn contains(&self, point: u32, v: [u32; 3]) -> bool {
        let mut node = self.roots[point as usize];
        let mut level = self.level_starts.len() as u32 - 1;
        loop {
            if level == 0 {
                let mask =
                    self.words[node as usize] as u64 | (self.words[node as usize + 1] as u64) << 32;
                return (mask >> morton::encode(v[0] & 3, v[1] & 3, v[2] & 3)) & 1 != 0;
            }
            let shift = level + 1;
            let c = ((v[0] >> shift) & 1) | ((v[1] >> shift) & 1) << 1 | ((v[2] >> shift) & 1) << 2;
            let mask = self.words[node as usize] & 0xff;
            if mask & (1 << c) == 0 {
                return false;
            }
            let rank = (mask & ((1 << c) - 1)).count_ones();
            node = self.words[(node + 1 + rank) as usize];
            level -= 1;
        }
    }

    /// Writes `proxies-R.bin` (layout in `docs/out-of-core.md`).
    pub fn write(&self, path: &Path) -> Result<(), OocError> {
        let mut bytes = Vec::with_capacity(32 + 4 * (self.words.len() + self.roots.len()));
        bytes.extend_from_slice(PROXY_MAGIC);
        for v in [
            PROXY_VERSION,
            self.resolution,
            self.roots.len() as u32,
            self.level_starts.len() as u32,
            self.words.len() as u32,
        ] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        for v in self
            .level_starts
            .iter()
            .chain(&self.roots)
            .chain(&self.words)
        {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let crc = crc32fast::hash(&bytes);
        bytes.extend_from_slice(&crc.to_le_bytes());
        crate::atomic_file::write_atomic(path, |w| w.write_all(&bytes))
            .map_err(|e| OocError::io(path, e))
    }

    /// Reads and fully validates a proxy file for `points` points.
    pub fn read(path: &Path, points: u32) -> Result<ProxySet, OocError> {
        let bytes = std::fs::read(path).map_err(|e| OocError::io(path, e))?;
        let mut r = super::format::Reader::new(path, &bytes);
        r.magic(PROXY_MAGIC)?;
        r.version(PROXY_VERSION)?;
        let at = r.offset();
        let resolution = r.u32()?;
        if !resolution.is_power_of_two() || !(8..=4096).contains(&resolution) {
            return Err(r.error(at, format!("bad proxy resolution {resolution}")));
        }
        let at = r.offset();
        let roots_n = r.u32()?;
        if roots_n != points {
            return Err(r.error(at, format!("{roots_n} proxies for {points} points")));
        }
        let at = r.offset();
        let levels = r.u32()?;
        if levels != resolution.trailing_zeros() - 1 {
            return Err(r.error(at, format!("{levels} levels for resolution {resolution}")));
        }
        let words_n = r.u32()?;
        let need = 4 * (levels as u64 + roots_n as u64 + words_n as u64) + 4;
        if (r.remaining() as u64) != need {
            return Err(r.error(
                r.offset(),
                format!("{} bytes left, the header needs {need}", r.remaining()),
            ));
        }
        r.check_crc()?;
        let body = r.offset();
        let level_starts = r.u32s(levels as usize)?;
        let roots = r.u32s(roots_n as usize)?;
        let words = r.u32s(words_n as usize)?;
        let words_at = body + 4 * (levels as u64 + roots_n as u64);
        let bad = |word: usize, why: String| r.error(words_at + 4 * word as u64, why);
        // Levels top-down: root level at word 0, each level before the next lower one.
        let root_level = levels as usize - 1;
        let mut ends = vec![0usize; levels as usize];
        for l in 0..levels as usize {
            let start = level_starts[l] as usize;
            let end = if l == 0 {
                words.len()
            } else {
                level_starts[l - 1] as usize
            };
            if (l == root_level && start != 0) || start >= end || end > words.len() {
                return Err(r.error(body + 4 * l as u64, format!("bad start of level {l}")));
            }
            ends[l] = end;
        }
        // Node starts per level; every pointer must name a node start in the level below.
        let mut starts_below: Vec<u32> = Vec::new();
        for l in 0..levels as usize {
            let (start, end) = (level_starts[l] as usize, ends[l]);
            let mut starts = Vec::new();
            let mut p = start;
            while p < end {
                starts.push(p as u32);
                if l == 0 {
                    if p + 2 > end || (words[p] == 0 && words[p + 1] == 0) {
                        return Err(bad(p, "bad leaf".into()));
                    }
                    p += 2;
                    continue;
                }
                let mask = words[p];
                if mask == 0 || mask > 0xff {
                    return Err(bad(p, format!("bad child mask {mask:#x}")));
                }
                let n = mask.count_ones() as usize;
                if p + 1 + n > end {
                    return Err(bad(p, "node runs past its level".into()));
                }
                for i in 0..n {
                    if starts_below.binary_search(&words[p + 1 + i]).is_err() {
                        return Err(bad(p + 1 + i, "child pointer is no node below".into()));
                    }
                }
                p += 1 + n;
            }
            starts_below = starts;
        }
        for (i, &root) in roots.iter().enumerate() {
            if starts_below.binary_search(&root).is_err() {
                return Err(r.error(
                    body + 4 * (levels as u64 + i as u64),
                    format!("root of point {i} is no root node"),
                ));
            }
        }
        Ok(ProxySet {
            resolution,
            words,
            level_starts,
            roots,
        })
    }
}
