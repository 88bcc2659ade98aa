//! Scene preparation: stream triangles (meshes with instance transforms, and optionally a
//! generated terrain), group them into spatially compact batching points and write the scene
//! directory with its proxies.
//!
//! Grouping: each triangle's centroid gets a 30-bit Morton code over the scene bounds. The
//! codes are cut into buckets by code prefixes, split further where an upper bound of their
//! triangles exceeds `bucket_bytes` (so a scene far larger than memory is never held at once,
//! however unevenly its triangles lie); each bucket's triangles are regenerated from the source when its turn
//! comes (only the mesh copies and terrain cells whose bounds reach the bucket's box are
//! produced, nothing is written to temporary files), sorted by code and split recursively at
//! the highest differing code bit (as an LBVH would) until a range holds at most
//! `batch_triangles` triangles: one batching point per range.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use indicatif::ProgressBar;
use rayon::prelude::*;

use super::format::{self, PointEntry, GEOMETRY_HEADER, TRI_BYTES};
use super::geom::{Aabb, Tri};
use super::proxy::{voxelize_point, Grid, ProxyBuilder};
use super::OocError;
use crate::dag::Svdag;
use crate::scene::morton;

/// An indexed triangle mesh in model space.
#[derive(Clone, Debug, Default)]
pub struct SourceMesh {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Triangles as vertex index triples (validated).
    pub triangles: Vec<[u32; 3]>,
}

impl SourceMesh {
    /// Positions and triangles of an imported mesh.
    pub fn from_mesh(mesh: &crate::scene::Mesh) -> Result<SourceMesh, OocError> {
        mesh.validate()?;
        Ok(SourceMesh {
            positions: mesh.positions.clone(),
            triangles: mesh.triangles.clone(),
        })
    }

    pub(super) fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in &self.positions {
            b.grow(*p);
        }
        b
    }
}

/// A copy of a mesh: `p' = M p + t` with `M` given row-major with `t` as the 4th column.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance {
    /// Index into [`SceneSource::meshes`].
    pub mesh: u32,
    /// Affine transform, row-major 3x4.
    pub transform: [[f64; 4]; 3],
}

impl Instance {
    /// Bounds of the copy of a mesh with bounds `mb`: its transformed corners, widened by a
    /// relative margin that covers the rounding of the transformed vertices.
    fn bounds(&self, mb: &Aabb) -> Aabb {
        let mut b = Aabb::EMPTY;
        for c in 0..8 {
            let p = [0, 1, 2].map(|k| if c >> k & 1 == 0 { mb.lo[k] } else { mb.hi[k] });
            let q = self.apply(p);
            b.grow(q.map(|v| v - v.abs() * 1e-6 - 1e-6));
            b.grow(q.map(|v| v + v.abs() * 1e-6 + 1e-6));
        }
        b
    }

    /// A copy of the mesh `mesh` (bounds `mb`) standing at `at`: scaled so that its largest
    /// extent is `extent`, rotated by `angle` about y around its centre, its lowest point
    /// sunk `sink` below `at`.
    pub fn standing(
        mesh: u32,
        mb: &Aabb,
        extent: f64,
        angle: f64,
        at: [f64; 3],
        sink: f64,
    ) -> Instance {
        let ext = (0..3)
            .map(|a| (mb.hi[a] - mb.lo[a]) as f64)
            .fold(0.0, f64::max)
            .max(1e-9);
        let scale = extent / ext;
        let c = mb.center();
        let (s, co) = (angle.sin() * scale, angle.cos() * scale);
        let [x, y, z] = at;
        // p' = R_y(angle) * scale * (p - centre_xz, p.y - min y) + (x, y - sink, z)
        let (cx, cz, miny) = (c[0] as f64, c[2] as f64, mb.lo[1] as f64);
        Instance {
            mesh,
            transform: [
                [co, 0.0, s, x - co * cx - s * cz],
                [0.0, scale, 0.0, y - scale * miny - sink],
                [-s, 0.0, co, z + s * cx - co * cz],
            ],
        }
    }

    fn apply(&self, p: [f32; 3]) -> [f32; 3] {
        let m = &self.transform;
        [0, 1, 2].map(|r| {
            (m[r][0] * p[0] as f64 + m[r][1] * p[1] as f64 + m[r][2] * p[2] as f64 + m[r][3]) as f32
        })
    }
}

/// A procedural height-field terrain of `2 cells^2` triangles over `[0, size]^2` in x/z (y up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Terrain {
    /// Cells per side.
    pub cells: u32,
    /// Side length in world units.
    pub size: f64,
    /// Height amplitude.
    pub height: f64,
    /// Noise seed.
    pub seed: u64,
}

/// splitmix64 finaliser: a well-mixed hash of a 64-bit value.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A uniform value in [0, 1) from a hash.
pub(super) fn unit(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

impl Terrain {
    /// Lattice value noise with smooth interpolation, 5 octaves.
    pub fn height_at(&self, x: f64, z: f64) -> f64 {
        let mut sum = 0.0;
        let mut amp = 0.5;
        let mut freq = 4.0 / self.size;
        for o in 0..5u64 {
            let (fx, fz) = (x * freq, z * freq);
            let (ix, iz) = (fx.floor(), fz.floor());
            let (tx, tz) = (fx - ix, fz - iz);
            let (sx, sz) = (tx * tx * (3.0 - 2.0 * tx), tz * tz * (3.0 - 2.0 * tz));
            let lattice = |a: f64, b: f64| {
                let h =
                    mix64(self.seed ^ mix64(o ^ mix64((a as i64 as u64) ^ mix64(b as i64 as u64))));
                unit(h) * 2.0 - 1.0
            };
            let v00 = lattice(ix, iz);
            let v10 = lattice(ix + 1.0, iz);
            let v01 = lattice(ix, iz + 1.0);
            let v11 = lattice(ix + 1.0, iz + 1.0);
            let a = v00 + (v10 - v00) * sx;
            let b = v01 + (v11 - v01) * sx;
            sum += amp * (a + (b - a) * sz);
            amp *= 0.5;
            freq *= 2.0;
        }
        sum * self.height
    }

    fn vertex(&self, i: u32, j: u32) -> [f32; 3] {
        let step = self.size / self.cells as f64;
        let (x, z) = (i as f64 * step, j as f64 * step);
        [x as f32, self.height_at(x, z) as f32, z as f32]
    }

    /// The triangles of cells `i0..i1` of row `j`, in cell order (each vertex evaluated once).
    fn row(&self, j: u32, i0: u32, i1: u32, out: &mut Vec<Tri>) {
        let near: Vec<[f32; 3]> = (i0..=i1).map(|i| self.vertex(i, j)).collect();
        let far: Vec<[f32; 3]> = (i0..=i1).map(|i| self.vertex(i, j + 1)).collect();
        for k in 0..(i1 - i0) as usize {
            let (a, b, c, d) = (near[k], near[k + 1], far[k], far[k + 1]);
            out.push([a, c, b]);
            out.push([b, c, d]);
        }
    }
}

/// The generated test scenes (`voxdag ooc generate --kind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GeneratedScene {
    /// Terrain and scattered copies of the meshes ([`SceneSource::landscape`]).
    Landscape,
    /// Terrain, groves of procedural trees and copies of the meshes ([`SceneSource::forest`]).
    Forest,
}

/// Everything a scene is made of, generated on demand in chunks (never all at once).
#[derive(Clone, Debug, Default)]
pub struct SceneSource {
    /// Meshes in model space.
    pub meshes: Vec<SourceMesh>,
    /// Placed copies of the meshes.
    pub instances: Vec<Instance>,
    /// An optional terrain.
    pub terrain: Option<Terrain>,
}

impl SceneSource {
    /// Total triangles.
    pub fn triangle_count(&self) -> u64 {
        let inst: u64 = self
            .instances
            .iter()
            .map(|i| self.meshes[i.mesh as usize].triangles.len() as u64)
            .sum();
        inst + self
            .terrain
            .map_or(0, |t| 2 * t.cells as u64 * t.cells as u64)
    }

    /// Bounds of all triangles (the transformed corners of each mesh's bounds, which hold its
    /// transformed vertices; the terrain's sampled heights).
    pub fn bounds(&self) -> Aabb {
        let mesh_bounds: Vec<Aabb> = self.meshes.iter().map(SourceMesh::bounds).collect();
        let mut b = Aabb::EMPTY;
        for inst in &self.instances {
            b.union(&inst.bounds(&mesh_bounds[inst.mesh as usize]));
        }
        if let Some(t) = &self.terrain {
            let h = t.height as f32;
            b.grow([0.0, -h, 0.0]);
            b.grow([t.size as f32, h, t.size as f32]);
        }
        b
    }

    /// The triangles whose centroid lies in `region`, in a fixed order (the terrain row by row, then the copies):
    /// regenerated from the meshes and the terrain (only the copies and terrain cells whose
    /// bounds reach the region), so a bucket of a scene larger than memory needs no file.
    fn region_triangles(&self, q: &Quantizer, region: &Region) -> Vec<(u32, Tri)> {
        let mut out: Vec<(u32, Tri)> = Vec::new();
        if let Some(t) = &self.terrain {
            let ((i0, i1), (j0, j1)) = terrain_cells(t, q, region);
            let rows: Vec<Vec<(u32, Tri)>> = (j0..j1)
                .into_par_iter()
                .map(|j| {
                    let mut tris = Vec::new();
                    if i1 > i0 {
                        t.row(j, i0, i1, &mut tris);
                    }
                    tris.into_iter()
                        .map(|tri| (q.code(&tri), tri))
                        .filter(|(c, _)| region.holds(*c))
                        .collect()
                })
                .collect();
            out.extend(rows.into_iter().flatten());
        }
        let mesh_bounds: Vec<Aabb> = self.meshes.iter().map(SourceMesh::bounds).collect();
        let copies: Vec<Vec<(u32, Tri)>> = self
            .instances
            .par_iter()
            .map(|inst| {
                let b = inst.bounds(&mesh_bounds[inst.mesh as usize]);
                if !region.overlaps(q.cell(b.lo), q.cell(b.hi)) {
                    return Vec::new();
                }
                let m = &self.meshes[inst.mesh as usize];
                let pos: Vec<[f32; 3]> = m.positions.iter().map(|&p| inst.apply(p)).collect();
                m.triangles
                    .iter()
                    .map(|tri| tri.map(|i| pos[i as usize]))
                    .map(|tri| (q.code(&tri), tri))
                    .filter(|(c, _)| region.holds(*c))
                    .collect()
            })
            .collect();
        out.extend(copies.into_iter().flatten());
        out
    }

    /// An upper bound of the triangles [`SceneSource::region_triangles`] returns for `region`:
    /// every triangle of the terrain cells and mesh copies it generates there.
    fn region_bound(&self, q: &Quantizer, region: &Region) -> u64 {
        let terrain = self.terrain.as_ref().map_or(0, |t| {
            let ((i0, i1), (j0, j1)) = terrain_cells(t, q, region);
            2 * (i1 - i0) as u64 * (j1 - j0) as u64
        });
        let mesh_bounds: Vec<Aabb> = self.meshes.iter().map(SourceMesh::bounds).collect();
        let copies: u64 = self
            .instances
            .par_iter()
            .filter(|inst| {
                let b = inst.bounds(&mesh_bounds[inst.mesh as usize]);
                region.overlaps(q.cell(b.lo), q.cell(b.hi))
            })
            .map(|inst| self.meshes[inst.mesh as usize].triangles.len() as u64)
            .sum();
        terrain + copies
    }

    /// The generated test scene `kind` of about `triangles` triangles from `meshes` and `seed`.
    pub fn generate(
        kind: GeneratedScene,
        meshes: Vec<SourceMesh>,
        triangles: u64,
        seed: u64,
    ) -> Result<SceneSource, OocError> {
        match kind {
            GeneratedScene::Landscape => SceneSource::landscape(meshes, triangles, seed),
            GeneratedScene::Forest => SceneSource::forest(meshes, triangles, seed),
        }
    }

    /// A landscape: a terrain of about a tenth of `triangles`, the rest copies of `meshes`
    /// (scaled, rotated about y and set on the terrain), all from `seed`.
    pub fn landscape(
        meshes: Vec<SourceMesh>,
        triangles: u64,
        seed: u64,
    ) -> Result<SceneSource, OocError> {
        let mut scene = SceneSource::terrain_for(meshes, triangles, seed)?;
        let bounds: Vec<Aabb> = scene.meshes.iter().map(SourceMesh::bounds).collect();
        scene.scatter_copies(&bounds, seed, triangles);
        Ok(scene)
    }

    /// Adds the landscape's copies of the first `bounds.len()` meshes (bounds `bounds`) until
    /// the scene holds `triangles`: the `k`-th copy is a mesh chosen from `seed` and `k`, its
    /// largest extent 1-4 % of the terrain's size, rotated about y and set on the terrain.
    pub(super) fn scatter_copies(&mut self, bounds: &[Aabb], seed: u64, triangles: u64) {
        let terrain = self.terrain.expect("generated scenes have a terrain");
        let size = terrain.size;
        let mut total = self.triangle_count();
        let mut k = 0u64;
        while total < triangles {
            let h = |d: u64| unit(mix64(seed ^ mix64(k * 16 + d)));
            let mesh = (h(0) * bounds.len() as f64) as usize % bounds.len();
            let extent = size * (0.01 + 0.03 * h(1));
            let angle = h(2) * std::f64::consts::TAU;
            let (x, z) = (h(3) * size, h(4) * size);
            let at = [x, terrain.height_at(x, z), z];
            let copy =
                Instance::standing(mesh as u32, &bounds[mesh], extent, angle, at, 0.002 * size);
            self.instances.push(copy);
            total += self.meshes[mesh].triangles.len() as u64;
            k += 1;
        }
    }

    /// The generated scenes' start: `meshes` with no copies yet, and a terrain of about a
    /// tenth of `triangles` over a 1000-unit square.
    pub(super) fn terrain_for(
        meshes: Vec<SourceMesh>,
        triangles: u64,
        seed: u64,
    ) -> Result<SceneSource, OocError> {
        if meshes.is_empty() || meshes.iter().any(|m| m.triangles.is_empty()) {
            return Err(OocError::Invalid(
                "the generated scenes need meshes with triangles".into(),
            ));
        }
        let terrain_tris = (triangles / 10).max(2);
        let cells = ((terrain_tris as f64 / 2.0).sqrt().ceil() as u32).max(1);
        Ok(SceneSource {
            meshes,
            instances: Vec::new(),
            terrain: Some(Terrain {
                cells,
                size: 1000.0,
                height: 60.0,
                seed,
            }),
        })
    }
}

/// Options of [`prepare`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PrepareOptions {
    /// Target triangles per batching point (points hold at most this many).
    pub batch_triangles: u32,
    /// Proxy resolutions to build (powers of two, 8..=4096): one `proxies-R.bin` each.
    pub proxy_resolutions: Vec<u32>,
    /// Bytes of triangles held in memory at once while grouping (sets the bucket count).
    pub bucket_bytes: u64,
}

impl Default for PrepareOptions {
    fn default() -> Self {
        PrepareOptions {
            batch_triangles: 100_000,
            proxy_resolutions: vec![128],
            bucket_bytes: 1 << 29,
        }
    }
}

/// What [`prepare`] wrote.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct PrepareSummary {
    /// Triangles written.
    pub triangles: u64,
    /// Batching points.
    pub points: u32,
    /// Bytes of `geometry.bin`.
    pub geometry_bytes: u64,
    /// Per proxy resolution: (resolution, words of the shared DAG, bytes in memory).
    pub proxies: Vec<(u32, u64, u64)>,
}

/// The 1024^3 grid over the scene bounds in which triangle centroids get their Morton codes.
struct Quantizer {
    lo: [f32; 3],
    inv: [f32; 3],
}

impl Quantizer {
    fn new(bounds: &Aabb) -> Quantizer {
        let inv = [0, 1, 2].map(|k| {
            let e = bounds.hi[k] - bounds.lo[k];
            if e > 0.0 {
                1024.0 / e
            } else {
                0.0
            }
        });
        Quantizer { lo: bounds.lo, inv }
    }

    /// Grid cell of a point (clamped; monotone in each coordinate).
    fn cell(&self, p: [f32; 3]) -> [u32; 3] {
        [0, 1, 2].map(|k| (((p[k] - self.lo[k]) * self.inv[k]).max(0.0) as u32).min(1023))
    }

    /// Morton code of a triangle's centroid (10 bits per axis).
    fn code(&self, t: &Tri) -> u32 {
        let c = [0, 1, 2].map(|k| (t[0][k] + t[1][k] + t[2][k]) / 3.0);
        let q = self.cell(c);
        morton::encode(q[0], q[1], q[2]) as u32
    }

    /// World span along axis `k` of the region's cells (unbounded at the grid's ends, where
    /// cells are clamped).
    fn world_span(&self, region: &Region, k: usize) -> (f64, f64) {
        if self.inv[k] == 0.0 {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        let (a, b) = (region.lo[k], region.hi[k]);
        let cell = 1.0 / self.inv[k] as f64;
        let lo = if a == 0 {
            f64::NEG_INFINITY
        } else {
            self.lo[k] as f64 + a as f64 * cell
        };
        let hi = if b == 1023 {
            f64::INFINITY
        } else {
            self.lo[k] as f64 + (b + 1) as f64 * cell
        };
        (lo, hi)
    }
}

/// The codes with a given top-bits prefix: a box of grid cells.
struct Region {
    prefix: u32,
    bits: u32,
    lo: [u32; 3],
    hi: [u32; 3],
}

impl Region {
    fn new(prefix: u32, bits: u32) -> Region {
        let lo = morton::decode((prefix as u64) << (30 - bits));
        // Bit 3i + k of a code is bit i of axis k: the prefix fixes the top bits of each axis.
        let fixed = [0, 1, 2].map(|k| (30 - bits..30).filter(|b| b % 3 == k).count() as u32);
        let hi = [0, 1, 2].map(|k| lo[k] + (1 << (10 - fixed[k])) - 1);
        Region {
            prefix,
            bits,
            lo,
            hi,
        }
    }

    fn holds(&self, code: u32) -> bool {
        self.bits == 0 || code >> (30 - self.bits) == self.prefix
    }

    /// True when the cell box `[a, b]` meets the region.
    fn overlaps(&self, a: [u32; 3], b: [u32; 3]) -> bool {
        (0..3).all(|k| a[k] <= self.hi[k] && b[k] >= self.lo[k])
    }
}

/// The terrain cells (x range, z range) whose x/z span reaches the region's (one cell of slack
/// for rounding).
fn terrain_cells(t: &Terrain, q: &Quantizer, region: &Region) -> ((u32, u32), (u32, u32)) {
    let step = t.size / t.cells as f64;
    let span = |k: usize| -> (u32, u32) {
        let (a, b) = q.world_span(region, k);
        let lo = ((a / step).floor() - 1.0).max(0.0);
        let hi = ((b / step).ceil() + 1.0).min(t.cells as f64);
        if hi <= lo {
            (0, 0)
        } else {
            (lo as u32, hi as u32)
        }
    };
    (span(0), span(2))
}

/// Most code bits a bucket prefix takes (a bucket of 2^-24 of the grid is 64 cells).
const MAX_BUCKET_BITS: u32 = 24;

/// The buckets of the grouping, in code order: the whole grid split at the next code bit
/// while a part may hold more than `bucket_bytes` of triangles by [`SceneSource::region_bound`]
/// (an upper bound, so no bucket's triangles exceed it unless one grid box of
/// `MAX_BUCKET_BITS` bits alone does). Uneven scenes (a landscape is flat: most of the grid's
/// height is empty) get small buckets where the triangles are and large ones elsewhere.
fn buckets(source: &SceneSource, q: &Quantizer, bucket_bytes: u64) -> Vec<Region> {
    let mut out = Vec::new();
    let mut todo = vec![Region::new(0, 0)];
    while let Some(region) = todo.pop() {
        if region.bits >= MAX_BUCKET_BITS
            || source.region_bound(q, &region) * TRI_BYTES <= bucket_bytes
        {
            out.push(region);
        } else {
            // Children pushed high first so that the low one is split or taken next.
            let (prefix, bits) = (region.prefix << 1, region.bits + 1);
            todo.push(Region::new(prefix | 1, bits));
            todo.push(Region::new(prefix, bits));
        }
    }
    out
}

/// Splits the sorted `codes[lo..hi]` into ranges of at most `k` at the highest differing bit.
fn split_points(codes: &[u32], lo: usize, hi: usize, k: usize, out: &mut Vec<(usize, usize)>) {
    if hi - lo <= k {
        out.push((lo, hi));
        return;
    }
    let (a, b) = (codes[lo], codes[hi - 1]);
    let mid = if a == b {
        (lo + hi) / 2
    } else {
        let bit = 31 - (a ^ b).leading_zeros();
        lo + codes[lo..hi].partition_point(|c| c >> bit & 1 == 0)
    };
    split_points(codes, lo, mid, k, out);
    split_points(codes, mid, hi, k, out);
}

fn tri_bytes(t: &Tri, out: &mut Vec<u8>) {
    for v in t {
        for c in v {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
}

/// Writes the scene directory `dir` for `source` (see the module docs).
pub fn prepare(
    source: &SceneSource,
    dir: &Path,
    options: &PrepareOptions,
    progress: &ProgressBar,
) -> Result<PrepareSummary, OocError> {
    if options.batch_triangles == 0 || options.batch_triangles > format::MAX_POINT_TRIANGLES {
        return Err(OocError::Invalid(format!(
            "--batch-triangles must be in 1..={}",
            format::MAX_POINT_TRIANGLES
        )));
    }
    for &r in &options.proxy_resolutions {
        if !r.is_power_of_two() || !(8..=4096).contains(&r) {
            return Err(OocError::Invalid(format!(
                "proxy resolution {r} is not a power of two in 8..=4096"
            )));
        }
    }
    let total = source.triangle_count();
    if total == 0 {
        return Err(OocError::Invalid("the scene has no triangles".into()));
    }
    std::fs::create_dir_all(dir).map_err(|e| OocError::io(dir, e))?;
    let q = Quantizer::new(&source.bounds());
    // Buckets by code prefixes, each regenerated from the source when its turn comes.
    let regions = buckets(source, &q, options.bucket_bytes);
    log::debug!("grouping {total} triangles in {} buckets", regions.len());
    progress.set_length(2 * total);
    progress.set_message("points");
    let geometry_path = dir.join(format::GEOMETRY_FILE);
    let mut offset = GEOMETRY_HEADER;
    let mut entries: Vec<PointEntry> = Vec::new();
    let mut builders: Vec<ProxyBuilder> = options
        .proxy_resolutions
        .iter()
        .map(|&r| ProxyBuilder::new(r))
        .collect();
    let mut write_points = |geo: &mut BufWriter<File>| -> Result<(), OocError> {
        let geo_error = |e: std::io::Error| OocError::io(&geometry_path, e);
        let mut head = Vec::new();
        head.extend_from_slice(format::GEOMETRY_MAGIC);
        head.extend_from_slice(&format::FORMAT_VERSION.to_le_bytes());
        head.extend_from_slice(&0u32.to_le_bytes());
        geo.write_all(&head).map_err(geo_error)?;
        for region in &regions {
            let mut keyed = source.region_triangles(&q, region);
            progress.inc(keyed.len() as u64);
            if keyed.is_empty() {
                continue;
            }
            keyed.par_sort_by_key(|k| k.0); // stable: equal codes keep input order
            let codes: Vec<u32> = keyed.iter().map(|k| k.0).collect();
            let tris: Vec<Tri> = keyed.into_iter().map(|k| k.1).collect();
            let mut ranges = Vec::new();
            split_points(
                &codes,
                0,
                codes.len(),
                options.batch_triangles as usize,
                &mut ranges,
            );
            // Per point: bounds, bytes, checksum and its proxies, in parallel.
            let per_point: Vec<(PointEntry, Vec<u8>, Vec<Svdag>)> = ranges
                .par_iter()
                .map(
                    |&(s, e)| -> Result<(PointEntry, Vec<u8>, Vec<Svdag>), OocError> {
                        let pts = &tris[s..e];
                        let mut pb = Aabb::EMPTY;
                        for t in pts {
                            pb.union(&Aabb::of_tri(t));
                        }
                        let mut bytes = Vec::with_capacity(pts.len() * TRI_BYTES as usize);
                        for t in pts {
                            tri_bytes(t, &mut bytes);
                        }
                        let dags = options
                            .proxy_resolutions
                            .iter()
                            .map(|&r| Svdag::from_voxels(&voxelize_point(pts, &Grid::new(&pb, r))))
                            .collect::<Result<Vec<_>, _>>()?;
                        let entry = PointEntry {
                            offset: 0,
                            triangles: pts.len() as u32,
                            crc: crc32fast::hash(&bytes),
                            bounds: pb,
                        };
                        Ok((entry, bytes, dags))
                    },
                )
                .collect::<Result<_, OocError>>()?;
            for (mut entry, bytes, dags) in per_point {
                entry.offset = offset;
                offset += bytes.len() as u64;
                geo.write_all(&bytes).map_err(geo_error)?;
                for (builder, dag) in builders.iter_mut().zip(&dags) {
                    builder.add(dag);
                }
                progress.inc(entry.triangles as u64);
                entries.push(entry);
            }
        }
        // The buckets partition the codes; a copy culled wrongly would show here.
        let written: u64 = entries.iter().map(|e| e.triangles as u64).sum();
        if written != total {
            return Err(OocError::Invalid(format!(
                "grouping produced {written} of {total} triangles"
            )));
        }
        Ok(())
    };
    // `write_atomic` (random exclusive temporary name, removed on error and on signals) only
    // carries an `io::Error`: the real error waits here.
    let mut failure = None;
    let written = crate::atomic_file::write_atomic(&geometry_path, |geo| {
        write_points(geo).map_err(|e| {
            let io = std::io::Error::other(e.to_string());
            failure = Some(e);
            io
        })
    });
    if let Some(e) = failure {
        return Err(e);
    }
    written.map_err(|e| OocError::io(&geometry_path, e))?;
    let mut scene_bounds = Aabb::EMPTY;
    for e in &entries {
        scene_bounds.union(&e.bounds);
    }
    let mut proxies = Vec::new();
    for builder in builders {
        let set = builder.finish();
        let path = dir.join(format::proxy_file(set.resolution));
        set.write(&path)?;
        proxies.push((set.resolution, set.words.len() as u64, set.bytes()));
    }
    let index = format::index_bytes(&entries, total, &scene_bounds, offset);
    let index_path = dir.join(format::INDEX_FILE);
    crate::atomic_file::write_atomic(&index_path, |w| w.write_all(&index))
        .map_err(|e| OocError::io(&index_path, e))?;
    progress.finish_and_clear();
    Ok(PrepareSummary {
        triangles: total,
        points: entries.len() as u32,
        geometry_bytes: offset,
        proxies,
    })
}
