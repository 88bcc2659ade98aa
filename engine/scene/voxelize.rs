//! Conservative surface voxelization of triangle meshes.
//!
//! A voxel `(x, y, z)` (the closed cube `[x, x+1] x [y, y+1] x [z, z+1]` in grid coordinates) is
//! set iff the closed triangle intersects it, decided by the separating-axis test of
//! Akenine-Möller in f64 ([`tri_box_overlap`]); touching counts. The fast path ([`voxelize`])
//! bins triangles into Morton-ordered bricks and tests, per triangle, only the voxels near its
//! plane; it produces exactly the set of [`voxelize_brute_force`] because both evaluate the same
//! predicate on the same f64 data and the candidate set of the fast path is a superset (with
//! margins) of the voxels that can pass. See `docs/voxelization.md`.

use indicatif::ProgressBar;
use rayon::prelude::*;

use super::mesh::{encode_rgba8, Mesh};
use super::morton;
use super::{SceneError, Voxels};

/// Log2 of the largest brick side used by [`voxelize`].
const BRICK_LOG: u32 = 7;

/// Largest grid a model is voxelized into: 2^17 per side (Morton codes of 51 bits, 2^10 bricks
/// per side; the f64 rounding of the predicate stays below 1e-8 voxels). The DAG, the file
/// format and the renderers take 2^21 (`dag::MAX_RESOLUTION`).
pub const MAX_VOXELIZE_RESOLUTION: u32 = 1 << 17;

/// Checks that `resolution` is a power of two in `8..=MAX_VOXELIZE_RESOLUTION`.
pub fn check_resolution(resolution: u32, path: &std::path::Path) -> Result<(), SceneError> {
    let reason = if !resolution.is_power_of_two() {
        "not a power of two".to_string()
    } else if resolution < 8 {
        "below the minimum 8".to_string()
    } else if resolution > MAX_VOXELIZE_RESOLUTION {
        format!("above the maximum {MAX_VOXELIZE_RESOLUTION}")
    } else {
        return Ok(());
    };
    Err(SceneError::BadResolution {
        path: path.to_path_buf(),
        resolution,
        reason,
    })
}

/// A triangle in f64 grid coordinates with the data the predicate needs.
#[derive(Clone, Copy, Debug)]
pub struct GridTriangle {
    /// Vertices in grid coordinates (voxel `(x, y, z)` spans `[x, x+1]` etc.).
    pub v: [[f64; 3]; 3],
    /// Edges `v1 - v0`, `v2 - v1`, `v0 - v2`.
    e: [[f64; 3]; 3],
    /// Normal `e0 x e1` (zero for degenerate triangles).
    n: [f64; 3],
    /// `0.5 * (|n.x| + |n.y| + |n.z|)`: the box radius along `n`.
    n_rad: f64,
}

#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
fn add_scaled(a: [f64; 3], s: f64, d: [f64; 3]) -> [f64; 3] {
    [a[0] + s * d[0], a[1] + s * d[1], a[2] + s * d[2]]
}

impl GridTriangle {
    /// Prepares a triangle given in grid coordinates.
    pub fn new(v: [[f64; 3]; 3]) -> GridTriangle {
        let e = [sub(v[1], v[0]), sub(v[2], v[1]), sub(v[0], v[2])];
        let n = cross(e[0], e[1]);
        let n_rad = 0.5 * (n[0].abs() + n[1].abs() + n[2].abs());
        GridTriangle { v, e, n, n_rad }
    }

    /// Axis-aligned bounds (min, max) of the vertices.
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = self.v[0];
        let mut hi = self.v[0];
        for p in &self.v[1..] {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        (lo, hi)
    }
}

/// Closed triangle / closed voxel intersection (separating-axis test, Akenine-Möller, in f64).
///
/// Axes: the 3 box normals, the triangle normal and the 9 cross products of triangle edges with
/// the box axes. An axis separates only if the projections are disjoint with a gap (`>`), so
/// touching counts as intersecting. A zero axis (degenerate triangle) never separates, which
/// leaves exactly the axes that are complete for a segment (box normals + edge x box axes) or
/// a point (box normals).
#[inline]
pub fn tri_box_overlap(t: &GridTriangle, voxel: [u32; 3]) -> bool {
    let c = [
        voxel[0] as f64 + 0.5,
        voxel[1] as f64 + 0.5,
        voxel[2] as f64 + 0.5,
    ];
    let v0 = sub(t.v[0], c);
    let v1 = sub(t.v[1], c);
    let v2 = sub(t.v[2], c);
    // Box normals.
    for a in 0..3 {
        let mn = v0[a].min(v1[a]).min(v2[a]);
        let mx = v0[a].max(v1[a]).max(v2[a]);
        if mn > 0.5 || mx < -0.5 {
            return false;
        }
    }
    // Triangle normal.
    {
        let p0 = dot(t.n, v0);
        let p1 = dot(t.n, v1);
        let p2 = dot(t.n, v2);
        let mn = p0.min(p1).min(p2);
        let mx = p0.max(p1).max(p2);
        if mn > t.n_rad || mx < -t.n_rad {
            return false;
        }
    }
    // Edge x box axis.
    for e in &t.e {
        // e x X = (0, e.z, -e.y)
        let axes = [[0.0, e[2], -e[1]], [-e[2], 0.0, e[0]], [e[1], -e[0], 0.0]];
        for ax in &axes {
            let p0 = dot(*ax, v0);
            let p1 = dot(*ax, v1);
            let p2 = dot(*ax, v2);
            let r = 0.5 * (ax[0].abs() + ax[1].abs() + ax[2].abs());
            let mn = p0.min(p1).min(p2);
            let mx = p0.max(p1).max(p2);
            if mn > r || mx < -r {
                return false;
            }
        }
    }
    true
}

/// Closest point of segment `a + t (b - a)`, `t in [0, 1]`, to `p`: returns `(t, point)`.
fn closest_on_segment(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> (f64, [f64; 3]) {
    let d = sub(b, a);
    let dd = dot(d, d);
    let t = if dd > 0.0 {
        (dot(sub(p, a), d) / dd).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (t, add_scaled(a, t, d))
}

/// Closest point of the closed triangle to `p` (Ericson, Real-Time Collision Detection 5.1.5),
/// with a segment fallback for degenerate triangles. Returns the squared distance and the
/// barycentric weights of the closest point.
pub fn closest_point(t: &GridTriangle, p: [f64; 3]) -> (f64, [f64; 3]) {
    let [a, b, c] = t.v;
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    let done = |q: [f64; 3], bary: [f64; 3]| {
        let d = sub(p, q);
        (dot(d, d), bary)
    };
    if d1 <= 0.0 && d2 <= 0.0 {
        return done(a, [1.0, 0.0, 0.0]);
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return done(b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 && d1 - d3 > 0.0 {
        let v = d1 / (d1 - d3);
        return done(add_scaled(a, v, ab), [1.0 - v, v, 0.0]);
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return done(c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 && d2 - d6 > 0.0 {
        let w = d2 / (d2 - d6);
        return done(add_scaled(a, w, ac), [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    let (e1, e2) = (d4 - d3, d5 - d6);
    if va <= 0.0 && e1 >= 0.0 && e2 >= 0.0 && e1 + e2 > 0.0 {
        let w = e1 / (e1 + e2);
        return done(add_scaled(b, w, sub(c, b)), [0.0, 1.0 - w, w]);
    }
    let sum = va + vb + vc;
    if sum > 0.0 && sum.is_finite() {
        let v = vb / sum;
        let w = vc / sum;
        if v.is_finite() && w.is_finite() {
            let q = add_scaled(add_scaled(a, v, ab), w, ac);
            return done(q, [1.0 - v - w, v, w]);
        }
    }
    // Degenerate (or numerically degenerate) triangle: nearest of the three edges,
    // first one wins ties.
    let mut best = (f64::INFINITY, [1.0, 0.0, 0.0]);
    for k in 0..3 {
        let (s, q) = closest_on_segment(p, t.v[k], t.v[(k + 1) % 3]);
        let d = sub(p, q);
        let d2 = dot(d, d);
        if d2 < best.0 {
            let mut bary = [0.0; 3];
            bary[k] = 1.0 - s;
            bary[(k + 1) % 3] = s;
            best = (d2, bary);
        }
    }
    best
}

/// Squared distance from the centre of `voxel` to triangle `t`, with the barycentric weights of
/// the closest point.
#[inline]
fn voxel_distance(t: &GridTriangle, voxel: [u32; 3]) -> (f64, [f64; 3]) {
    closest_point(
        t,
        [
            voxel[0] as f64 + 0.5,
            voxel[1] as f64 + 0.5,
            voxel[2] as f64 + 0.5,
        ],
    )
}

/// The triangles of a validated mesh mapped into grid coordinates: the bounding box is scaled
/// uniformly so its longest side spans `[0, N]` and centred on the other axes.
pub fn grid_triangles(mesh: &Mesh, resolution: u32) -> Result<Vec<GridTriangle>, SceneError> {
    mesh.validate()?;
    if mesh.triangles.is_empty() {
        return Err(SceneError::InvalidMesh {
            path: mesh.source.clone(),
            reason: "the mesh has no triangles".into(),
        });
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for tri in &mesh.triangles {
        for &i in tri {
            let p = mesh.positions[i as usize];
            for a in 0..3 {
                lo[a] = lo[a].min(p[a] as f64);
                hi[a] = hi[a].max(p[a] as f64);
            }
        }
    }
    let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let longest = ext[0].max(ext[1]).max(ext[2]);
    if longest <= 0.0 || !longest.is_finite() {
        return Err(SceneError::InvalidMesh {
            path: mesh.source.clone(),
            reason: format!("the mesh bounding box has no extent ({ext:?})"),
        });
    }
    let n = resolution as f64;
    let scale = n / longest;
    let offset = [
        (n - ext[0] * scale) * 0.5,
        (n - ext[1] * scale) * 0.5,
        (n - ext[2] * scale) * 0.5,
    ];
    let map = |i: u32| {
        let p = mesh.positions[i as usize];
        let mut g = [0f64; 3];
        for a in 0..3 {
            g[a] = (p[a] as f64 - lo[a]) * scale + offset[a];
        }
        g
    };
    Ok(mesh
        .triangles
        .par_iter()
        .map(|t| GridTriangle::new([map(t[0]), map(t[1]), map(t[2])]))
        .collect())
}

/// Inclusive voxel index range `[lo, hi]` that can contain voxels touching `t` (with a margin
/// of one voxel), clamped to the grid; `None` when empty.
fn voxel_range(t: &GridTriangle, resolution: u32) -> Option<([u32; 3], [u32; 3])> {
    let (lo, hi) = t.bounds();
    let max = resolution as f64 - 1.0;
    let mut l = [0u32; 3];
    let mut h = [0u32; 3];
    for a in 0..3 {
        let a_lo = (lo[a].floor() - 1.0).max(0.0);
        let a_hi = (hi[a].floor() + 1.0).min(max);
        if a_lo > a_hi {
            return None;
        }
        l[a] = a_lo as u32;
        h[a] = a_hi as u32;
    }
    Some((l, h))
}

/// Rough memory need of a voxelization, as `(voxels, bytes)`: the surface area in voxel units
/// divided by sqrt(2) (the largest cross-section of a unit cube) is a lower bound on the voxel
/// count of a non-overlapping surface. A degenerate triangle (zero normal: a segment or a
/// point) has no area but still sets voxels: it counts the longest side of its bounding box
/// (a connected set spanning a length `l` along an axis meets at least `l` voxel slabs), at
/// least one voxel.
fn estimate_bytes(tris: &[GridTriangle], has_colors: bool) -> (f64, f64) {
    let voxels: f64 = tris
        .par_iter()
        .map(|t| {
            if is_degenerate(t) {
                let (lo, hi) = t.bounds();
                let l = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
                if l.is_finite() {
                    l.max(1.0)
                } else {
                    1.0
                }
            } else {
                0.5 * dot(t.n, t.n).sqrt() / std::f64::consts::SQRT_2
            }
        })
        .sum();
    let per_voxel = if has_colors { 12.0 } else { 8.0 };
    (voxels, voxels * per_voxel)
}

/// Available memory from `/proc/meminfo` (`MemAvailable`), if readable (the one place the
/// memory guards of [`voxelize`] and [`super::load_vox`] read it).
pub(crate) fn mem_available() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = s.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb.saturating_mul(1024))
}

/// Per-thread scratch space for one brick.
struct Scratch {
    bits: Vec<u64>,
    best_d2: Vec<f64>,
    best_tri: Vec<u32>,
}

/// Output of one brick: Morton codes (ascending) and colours.
type BrickOut = (Vec<u64>, Vec<u32>);

/// Everything the brick workers share.
struct Ctx<'a> {
    mesh: &'a Mesh,
    tris: &'a [GridTriangle],
    resolution: u32,
    brick_log: u32,
    colors: bool,
}

/// Margin (in voxels) that every candidate range carries beyond the exact geometry, far above
/// the f64 rounding error of the predicate and the ranges (below 1e-8 voxels at N = 2^17).
const MARGIN: f64 = 1e-3;

/// True for a triangle whose normal is zero (a segment or a point) or not finite. Such a
/// triangle has no plane to enumerate candidates from; [`for_candidates`] walks its edges.
#[inline]
fn is_degenerate(t: &GridTriangle) -> bool {
    t.n.iter().all(|&c| c == 0.0) || t.n.iter().any(|c| !c.is_finite())
}

/// Parameter sub-range of `[t0, t1]` where `p + t d` lies in `[lo, hi]`; `None` if empty.
#[inline]
fn clip_axis(p: f64, d: f64, lo: f64, hi: f64, t0: f64, t1: f64) -> Option<(f64, f64)> {
    if d == 0.0 {
        return (!(p < lo || p > hi)).then_some((t0, t1));
    }
    let ta = (lo - p) / d;
    let tb = (hi - p) / d;
    let (ta, tb) = if ta <= tb { (ta, tb) } else { (tb, ta) };
    let (s0, s1) = (ta.max(t0), tb.min(t1));
    (s0 <= s1).then_some((s0, s1))
}

/// Calls `f` for every cell `c` in `[lo, hi]` (cell indices; cells of side `2^cell_log`
/// voxels) whose closed box, grown by `margin` voxels on every side, meets the closed segment
/// `a`-`b` (grid coordinates; `a == b` is a point). Cost: O(1) when no cell qualifies, else
/// O(cells visited): the segment is clipped to the grown box of `[lo, hi]`, then walked one
/// cell slab at a time along its dominant axis; in each slab the other two axes span at most
/// `1 + 2 margin` cells' worth of length, so at most 3 x 3 cells per slab. Loops are bounded by
/// `[lo, hi]` even for non-finite input.
fn for_segment_cells(
    a: [f64; 3],
    b: [f64; 3],
    cell_log: u32,
    margin: f64,
    lo: [u32; 3],
    hi: [u32; 3],
    f: &mut impl FnMut([u32; 3]),
) {
    // Scaling by a power of two is exact.
    let inv = 1.0 / (1u64 << cell_log) as f64;
    let a = a.map(|x| x * inv);
    let b = b.map(|x| x * inv);
    let m = margin * inv;
    let d = sub(b, a);
    let (mut t0, mut t1) = (0.0, 1.0);
    for ax in 0..3 {
        match clip_axis(
            a[ax],
            d[ax],
            lo[ax] as f64 - m,
            hi[ax] as f64 + 1.0 + m,
            t0,
            t1,
        ) {
            Some(r) => (t0, t1) = r,
            None => return,
        }
    }
    let ad = d.map(f64::abs);
    let w = if ad[0] >= ad[1] && ad[0] >= ad[2] {
        0
    } else if ad[1] >= ad[2] {
        1
    } else {
        2
    };
    let (u, v) = ((w + 1) % 3, (w + 2) % 3);
    // Closed cells [i, i + 1] grown by m that meet the coordinate range [p, q] of `ax`.
    let cells = |ax: usize, p: f64, q: f64| -> Option<(u32, u32)> {
        let c_lo = (p.min(q) - m - 1.0).ceil().max(lo[ax] as f64);
        let c_hi = (p.max(q) + m).floor().min(hi[ax] as f64);
        (c_lo <= c_hi).then_some((c_lo as u32, c_hi as u32))
    };
    let Some((k_lo, k_hi)) = cells(w, a[w] + t0 * d[w], a[w] + t1 * d[w]) else {
        return;
    };
    for k in k_lo..=k_hi {
        let Some((s0, s1)) = clip_axis(a[w], d[w], k as f64 - m, k as f64 + 1.0 + m, t0, t1) else {
            continue;
        };
        let Some((u_lo, u_hi)) = cells(u, a[u] + s0 * d[u], a[u] + s1 * d[u]) else {
            continue;
        };
        let Some((v_lo, v_hi)) = cells(v, a[v] + s0 * d[v], a[v] + s1 * d[v]) else {
            continue;
        };
        for cu in u_lo..=u_hi {
            for cv in v_lo..=v_hi {
                let mut c = [0u32; 3];
                c[w] = k;
                c[u] = cu;
                c[v] = cv;
                f(c);
            }
        }
    }
}

/// Calls `f` for every voxel in `[lo, hi]` that may intersect `t` (a superset of the voxels
/// passing [`tri_box_overlap`]): every column of the dominant normal axis, limited to the
/// plane's range within the column plus a margin; for a degenerate triangle, the voxels near
/// its edges ([`for_segment_cells`]).
#[inline]
fn for_candidates(t: &GridTriangle, lo: [u32; 3], hi: [u32; 3], mut f: impl FnMut([u32; 3])) {
    let n = t.n;
    let an = [n[0].abs(), n[1].abs(), n[2].abs()];
    let w = if an[0] >= an[1] && an[0] >= an[2] {
        0
    } else if an[1] >= an[2] {
        1
    } else {
        2
    };
    let (u, v) = ((w + 1) % 3, (w + 2) % 3);
    if is_degenerate(t) {
        // Zero normal: the triangle is a segment or a point (or, after rounding, a sliver far
        // thinner than MARGIN), i.e. within MARGIN of the union of its edges. Some voxels
        // may be visited twice (shared neighbourhoods); the caller is idempotent.
        for k in 0..3 {
            for_segment_cells(t.v[k], t.v[(k + 1) % 3], 0, MARGIN, lo, hi, &mut f);
        }
        return;
    }
    // The normal test passes only if n.c lies in [pmin - r, pmax + r] (up to rounding, which is
    // below 1e-8 voxels at 2^17; the margin is 1e-3 voxels).
    let p = [dot(n, t.v[0]), dot(n, t.v[1]), dot(n, t.v[2])];
    let pmin = p[0].min(p[1]).min(p[2]) - t.n_rad;
    let pmax = p[0].max(p[1]).max(p[2]) + t.n_rad;
    for cu in lo[u]..=hi[u] {
        let su = n[u] * (cu as f64 + 0.5);
        // Columns of this row that the triangle's projection can touch: the v-extent of the
        // triangle clipped to the slab u in [cu, cu + 1] (with margins).
        let Some((v_lo, v_hi)) = slab_range(t, u, v, cu as f64 - MARGIN, cu as f64 + 1.0 + MARGIN)
        else {
            continue;
        };
        let cv_lo = ((v_lo - MARGIN - 1.0).ceil().max(lo[v] as f64)) as u32;
        let cv_hi = (v_hi + MARGIN).floor().min(hi[v] as f64);
        if cv_hi < cv_lo as f64 {
            continue;
        }
        for cv in cv_lo..=cv_hi as u32 {
            let s = su + n[v] * (cv as f64 + 0.5);
            let a = (pmin - s) / n[w];
            let b = (pmax - s) / n[w];
            let (a, b) = if a <= b { (a, b) } else { (b, a) };
            // centre c_w = k + 0.5 in [a, b]
            let k_lo = (a - MARGIN - 0.5).ceil().max(lo[w] as f64);
            let k_hi = (b + MARGIN - 0.5).floor().min(hi[w] as f64);
            if k_lo.is_nan() || k_hi.is_nan() || k_lo > k_hi {
                continue;
            }
            for k in k_lo as u32..=k_hi as u32 {
                let mut c = [0u32; 3];
                c[u] = cu;
                c[v] = cv;
                c[w] = k;
                f(c);
            }
        }
    }
}

/// Range of coordinate `v` over the part of triangle `t` whose coordinate `u` lies in
/// `[a, b]`; `None` if that part is empty.
#[inline]
fn slab_range(t: &GridTriangle, u: usize, v: usize, a: f64, b: f64) -> Option<(f64, f64)> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for k in 0..3 {
        let p = t.v[k];
        let q = t.v[(k + 1) % 3];
        let (pu, qu) = (p[u], q[u]);
        let du = qu - pu;
        let (t0, t1) = if du == 0.0 {
            if pu < a || pu > b {
                continue;
            }
            (0.0, 1.0)
        } else {
            let ta = (a - pu) / du;
            let tb = (b - pu) / du;
            let (ta, tb) = if ta <= tb { (ta, tb) } else { (tb, ta) };
            let (t0, t1) = (ta.max(0.0), tb.min(1.0));
            if t0 > t1 {
                continue;
            }
            (t0, t1)
        };
        let dv = q[v] - p[v];
        for tt in [t0, t1] {
            let pv = p[v] + tt * dv;
            lo = lo.min(pv);
            hi = hi.max(pv);
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// Voxelizes one brick (Morton code `brick` of the brick grid) from its triangle list.
fn voxelize_brick(ctx: &Ctx, scratch: &mut Scratch, brick: u64, tri_ids: &[u64]) -> BrickOut {
    let bl = ctx.brick_log;
    let side = 1u32 << bl;
    let [bx, by, bz] = morton::decode(brick);
    let base = [bx << bl, by << bl, bz << bl];
    let words = (1usize << (3 * bl)) / 64;
    scratch.bits.clear();
    scratch.bits.resize(words, 0);
    if ctx.colors && scratch.best_d2.len() < (1usize << (3 * bl)) {
        scratch.best_d2.resize(1 << (3 * bl), 0.0);
        scratch.best_tri.resize(1 << (3 * bl), 0);
    }
    for &id in tri_ids {
        let ti = (id & 0xffff_ffff) as u32;
        let t = &ctx.tris[ti as usize];
        let Some((mut lo, mut hi)) = voxel_range(t, ctx.resolution) else {
            continue;
        };
        let mut empty = false;
        for a in 0..3 {
            lo[a] = lo[a].max(base[a]);
            hi[a] = hi[a].min(base[a] + side - 1);
            empty |= lo[a] > hi[a];
        }
        if empty {
            continue;
        }
        for_candidates(t, lo, hi, |c| {
            if !tri_box_overlap(t, c) {
                return;
            }
            let local = morton::encode(c[0] - base[0], c[1] - base[1], c[2] - base[2]) as usize;
            let (word, bit) = (local >> 6, 1u64 << (local & 63));
            let fresh = scratch.bits[word] & bit == 0;
            scratch.bits[word] |= bit;
            if ctx.colors {
                let (d2, _) = voxel_distance(t, c);
                if fresh
                    || d2 < scratch.best_d2[local]
                    || (d2 == scratch.best_d2[local] && ti < scratch.best_tri[local])
                {
                    scratch.best_d2[local] = d2;
                    scratch.best_tri[local] = ti;
                }
            }
        });
    }
    let count: usize = scratch.bits.iter().map(|w| w.count_ones() as usize).sum();
    let mut codes = Vec::with_capacity(count);
    let mut colors = Vec::with_capacity(if ctx.colors { count } else { 0 });
    let high = brick << (3 * bl);
    for (wi, &word) in scratch.bits.iter().enumerate() {
        let mut w = word;
        while w != 0 {
            let b = w.trailing_zeros() as usize;
            w &= w - 1;
            let local = (wi << 6) | b;
            codes.push(high | local as u64);
            if ctx.colors {
                let ti = scratch.best_tri[local] as usize;
                let l = morton::decode(local as u64);
                let c = [base[0] + l[0], base[1] + l[1], base[2] + l[2]];
                let (_, bary) = voxel_distance(&ctx.tris[ti], c);
                colors.push(encode_rgba8(ctx.mesh.color_at(ti, bary)));
            }
        }
    }
    (codes, colors)
}

/// Conservative surface voxelization at `resolution` (power of two, 8..=131072), multithreaded
/// with rayon; `progress` counts bricks. Output is sorted by Morton code and unique. Colour
/// rule: among the triangles intersecting a voxel, the one whose closest point to the voxel
/// centre is nearest (ties: lowest triangle index), sampled at that closest point.
pub fn voxelize(
    mesh: &Mesh,
    resolution: u32,
    progress: &ProgressBar,
) -> Result<Voxels, SceneError> {
    check_resolution(resolution, &mesh.source)?;
    let tris = grid_triangles(mesh, resolution)?;
    let colors = mesh.has_colors;
    let (est_voxels, est_bytes) = estimate_bytes(&tris, colors);
    crate::safety::check_memory(
        format!(
            "voxelizing {} at resolution {resolution} (about {:.0} M voxels)",
            mesh.source.display(),
            est_voxels / 1e6
        ),
        est_bytes as u64,
    )
    .map_err(|e| SceneError::TooLarge {
        path: mesh.source.clone(),
        reason: e.to_string(),
    })?;
    if let Some(avail) = mem_available() {
        if est_bytes > avail as f64 {
            return Err(SceneError::TooLarge {
                path: mesh.source.clone(),
                reason: format!(
                    "about {:.0} M voxels ({:.1} GiB) at resolution {resolution} but only \
                     {:.1} GiB of memory is available",
                    est_voxels / 1e6,
                    est_bytes / (1u64 << 30) as f64,
                    avail as f64 / (1u64 << 30) as f64
                ),
            });
        }
    }
    let mut out = Voxels {
        resolution,
        codes: Vec::new(),
        colors: Vec::new(),
    };
    voxelize_tris(mesh, &tris, resolution, 0..u64::MAX, progress, |c, col| {
        // The estimate can be short: grow fallibly, an error rather than an abort.
        let grown = out.codes.len() as u64 + c.len() as u64;
        let bytes = grown * if colors { 12 } else { 8 };
        crate::safety::check_memory("the voxel arrays", bytes).map_err(|e| {
            SceneError::TooLarge {
                path: mesh.source.clone(),
                reason: e.to_string(),
            }
        })?;
        let reserved =
            out.codes.try_reserve(c.len()).is_ok() && out.colors.try_reserve(col.len()).is_ok();
        if !reserved {
            return Err(SceneError::TooLarge {
                path: mesh.source.clone(),
                reason: format!("out of memory for {grown} voxels"),
            });
        }
        out.codes.extend_from_slice(c);
        out.colors.extend_from_slice(col);
        Ok(())
    })?;
    out.codes.shrink_to_fit();
    out.colors.shrink_to_fit();
    Ok(out)
}

/// Voxelizes `mesh` at `resolution` without collecting the voxels: hands every brick's
/// ascending Morton codes (and colours, empty when the mesh has none) to `sink`, bricks in
/// Morton order, so the concatenation of what `sink` sees is [`voxelize`]'s output. Two
/// groups of bricks (64 per thread) are held at a time: `sink` runs on one of the pool's
/// threads while the next group is voxelized. No memory guard: the caller bounds
/// what it keeps (the streaming build, `docs/scaling.md`). Stops at the first error of `sink`.
pub fn voxelize_stream<E: From<SceneError> + Send>(
    mesh: &Mesh,
    resolution: u32,
    progress: &ProgressBar,
    sink: impl FnMut(&[u64], &[u32]) -> Result<(), E> + Send,
) -> Result<(), E> {
    voxelize_stream_range(mesh, resolution, 0..u64::MAX, progress, sink)
}

/// [`voxelize_stream`] of the voxels whose Morton codes lie in `range` only (a part of a
/// partitioned build, `docs/scaling.md`): bricks outside it are not voxelized.
pub fn voxelize_stream_range<E: From<SceneError> + Send>(
    mesh: &Mesh,
    resolution: u32,
    range: std::ops::Range<u64>,
    progress: &ProgressBar,
    mut sink: impl FnMut(&[u64], &[u32]) -> Result<(), E> + Send,
) -> Result<(), E> {
    check_resolution(resolution, &mesh.source)?;
    let tris = grid_triangles(mesh, resolution)?;
    let inside = range.clone();
    voxelize_tris(mesh, &tris, resolution, range, progress, |codes, colors| {
        let from = codes.partition_point(|&c| c < inside.start);
        let to = codes.partition_point(|&c| c < inside.end);
        if from == to {
            return Ok(());
        }
        let colors = if colors.is_empty() {
            colors
        } else {
            &colors[from..to]
        };
        sink(&codes[from..to], colors)
    })
}

/// Estimated surface voxels of `mesh` at `resolution` (the lower bound of the memory guard of
/// [`voxelize`]: surface area / sqrt(2), degenerate triangles by their longest side).
pub fn estimate_voxels(mesh: &Mesh, resolution: u32) -> Result<f64, SceneError> {
    check_resolution(resolution, &mesh.source)?;
    let tris = grid_triangles(mesh, resolution)?;
    Ok(estimate_bytes(&tris, false).0)
}

/// Bytes the streaming voxelizer holds besides the mesh for `triangles` triangles: the grid
/// triangles, the brick bins (at most 27 bricks per triangle assumed: a triangle smaller than
/// a brick meets at most 3 per axis) and per thread a brick's scratch space and one group of
/// bricks' output at `voxels_per_brick` (two groups: one voxelized while the other is consumed).
pub fn stream_working_set(triangles: usize, colors: bool, voxels_per_brick: f64) -> u64 {
    let threads = rayon::current_num_threads().max(1) as u64;
    let cells = 1u64 << (3 * BRICK_LOG);
    let scratch = cells / 8 + if colors { cells * 12 } else { 0 };
    let per_voxel = if colors { 12.0 } else { 8.0 };
    let group = 2.0 * (64 * threads) as f64 * voxels_per_brick * per_voxel;
    let tris = triangles as u64 * (std::mem::size_of::<GridTriangle>() as u64 + 27 * 8);
    tris + threads * scratch + group as u64
}

/// The brick loop of [`voxelize`] and [`voxelize_stream`] on prepared grid triangles.
fn voxelize_tris<E: From<SceneError> + Send>(
    mesh: &Mesh,
    tris: &[GridTriangle],
    resolution: u32,
    range: std::ops::Range<u64>,
    progress: &ProgressBar,
    mut sink: impl FnMut(&[u64], &[u32]) -> Result<(), E> + Send,
) -> Result<(), E> {
    let colors = mesh.has_colors;
    let res_log = resolution.trailing_zeros();
    let brick_log = BRICK_LOG.min(res_log);
    // Bin triangles into bricks: key = brick Morton code << 32 | triangle index. A triangle
    // goes to every brick of its voxel range; a degenerate one (segment) only to the bricks
    // near its edges (a superset of the bricks holding its voxel candidates, which are the
    // voxels near its edges): a long diagonal segment would otherwise fill (N / 128)^3 bins.
    let mut pairs: Vec<u64> = tris
        .par_iter()
        .enumerate()
        .flat_map_iter(|(i, t)| {
            let range = voxel_range(t, resolution);
            let (mut blo, mut bhi) = match range {
                Some((lo, hi)) => (lo.map(|c| c >> brick_log), hi.map(|c| c >> brick_log)),
                None => ([1; 3], [0; 3]),
            };
            let mut near_edges: Vec<u64> = Vec::new();
            if range.is_some() && is_degenerate(t) {
                let mut push = |b: [u32; 3]| near_edges.push(morton::encode(b[0], b[1], b[2]));
                for k in 0..3 {
                    let (a, b) = (t.v[k], t.v[(k + 1) % 3]);
                    for_segment_cells(a, b, brick_log, MARGIN, blo, bhi, &mut push);
                }
                near_edges.sort_unstable();
                near_edges.dedup();
                (blo, bhi) = ([1; 3], [0; 3]);
            }
            let key = move |code: u64| (code << 32) | i as u64;
            near_edges
                .into_iter()
                .map(key)
                .chain((blo[2]..=bhi[2]).flat_map(move |z| {
                    (blo[1]..=bhi[1]).flat_map(move |y| {
                        (blo[0]..=bhi[0]).map(move |x| key(morton::encode(x, y, z)))
                    })
                }))
        })
        .collect();
    pairs.par_sort_unstable();
    // Brick boundaries.
    let mut bricks: Vec<(u64, usize, usize)> = Vec::new();
    let mut start = 0;
    for i in 1..=pairs.len() {
        if i == pairs.len() || pairs[i] >> 32 != pairs[start] >> 32 {
            let brick = pairs[start] >> 32;
            // Bricks are contiguous runs of Morton codes: skip those outside `range`.
            let (lo, hi) = (brick << (3 * brick_log), (brick + 1) << (3 * brick_log));
            if hi > range.start && lo < range.end {
                bricks.push((brick, start, i));
            }
            start = i;
        }
    }
    progress.set_message("voxelizing");
    progress.set_length(bricks.len() as u64);
    progress.set_position(0);
    let ctx = Ctx {
        mesh,
        tris,
        resolution,
        brick_log,
        colors,
    };
    let chunk = 64 * rayon::current_num_threads().max(1);
    // Pipelined: the sink consumes one group (on one thread) while the next is voxelized.
    let mut pending: Option<Vec<BrickOut>> = None;
    let mut drain = |results: &[BrickOut]| -> Result<(), E> {
        for (c, col) in results {
            sink(c, col)?;
        }
        Ok(())
    };
    for group in bricks.chunks(chunk) {
        let compute = || -> Vec<BrickOut> {
            group
                .par_iter()
                .map_init(
                    || Scratch {
                        bits: Vec::new(),
                        best_d2: Vec::new(),
                        best_tri: Vec::new(),
                    },
                    |s, &(b, from, to)| voxelize_brick(&ctx, s, b, &pairs[from..to]),
                )
                .collect()
        };
        let results = match pending.take() {
            Some(previous) => {
                let (results, drained) = rayon::join(compute, || drain(&previous));
                drained?;
                results
            }
            None => compute(),
        };
        pending = Some(results);
        progress.inc(group.len() as u64);
    }
    if let Some(previous) = pending {
        drain(&previous)?;
    }
    Ok(())
}

/// Reference voxelizer: tests every voxel of the grid against every triangle with
/// [`tri_box_overlap`] and applies the same colour rule as [`voxelize`]. O(N^3 * triangles):
/// small resolutions only. Panics on an invalid mesh or resolution (test helper).
pub fn voxelize_brute_force(mesh: &Mesh, resolution: u32) -> Voxels {
    check_resolution(resolution, &mesh.source).expect("valid resolution");
    let tris = grid_triangles(mesh, resolution).expect("valid mesh");
    let n = resolution;
    let colors = mesh.has_colors;
    let mut found: Vec<(u64, u32)> = (0..n)
        .into_par_iter()
        .flat_map_iter(|z| {
            let tris = &tris;
            (0..n).flat_map(move |y| {
                (0..n).filter_map(move |x| {
                    let c = [x, y, z];
                    let mut best: Option<(f64, usize, [f64; 3])> = None;
                    for (i, t) in tris.iter().enumerate() {
                        if !tri_box_overlap(t, c) {
                            continue;
                        }
                        if !colors {
                            best = Some((0.0, i, [0.0; 3]));
                            break;
                        }
                        let (d2, bary) = voxel_distance(t, c);
                        if best.is_none_or(|(bd, _, _)| d2 < bd) {
                            best = Some((d2, i, bary));
                        }
                    }
                    best.map(|(_, i, bary)| {
                        let col = if colors {
                            encode_rgba8(mesh.color_at(i, bary))
                        } else {
                            0
                        };
                        (morton::encode(x, y, z), col)
                    })
                })
            })
        })
        .collect();
    found.par_sort_unstable_by_key(|p| p.0);
    Voxels {
        resolution,
        codes: found.iter().map(|p| p.0).collect(),
        colors: if colors {
            found.iter().map(|p| p.1).collect()
        } else {
            Vec::new()
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degenerate_triangles_count_their_length_in_the_estimate() {
        let seg = GridTriangle::new([[1.0, 2.0, 3.0], [101.0, 42.0, 3.0], [51.0, 22.0, 3.0]]);
        let point = GridTriangle::new([[5.5; 3]; 3]);
        assert!(is_degenerate(&seg) && is_degenerate(&point));
        let (voxels, bytes) = estimate_bytes(&[seg], false);
        assert_eq!(voxels, 100.0);
        assert_eq!(bytes, 800.0);
        assert_eq!(estimate_bytes(&[point], true), (1.0, 12.0));
        // A proper triangle still counts area / sqrt(2).
        let tri = GridTriangle::new([[0.0; 3], [4.0, 0.0, 0.0], [0.0, 4.0, 0.0]]);
        assert!(!is_degenerate(&tri));
        assert_eq!(
            estimate_bytes(&[tri], false).0,
            8.0 / std::f64::consts::SQRT_2
        );
    }

    #[test]
    fn segment_cells_cover_the_closed_neighbourhood() {
        // Sampled brute force on a small grid: every cell whose box grown by the margin meets
        // the segment is reported (the superset the exact predicate needs), each once, and
        // every reported cell is within one cell of the segment (the per-slab box).
        let cases = [
            ([0.5, 0.5, 0.5], [6.5, 2.5, 0.5]),
            ([2.0, 2.0, 2.0], [2.0, 2.0, 2.0]),
            ([0.0, 7.0, 3.0], [7.0, 0.0, 3.0]),
            ([1.25, 6.0, 2.75], [5.5, 1.0, 7.0]),
            ([7.9, 0.1, 4.0], [0.2, 7.7, 4.5]),
        ];
        let near = |a: [f64; 3], b: [f64; 3], c: [u32; 3], grow: f64| {
            (0..=4096).any(|i| {
                let s = i as f64 / 4096.0;
                (0..3).all(|k| {
                    let p = a[k] + s * (b[k] - a[k]);
                    p >= c[k] as f64 - grow && p <= c[k] as f64 + 1.0 + grow
                })
            })
        };
        for (a, b) in cases {
            let mut got = Vec::new();
            for_segment_cells(a, b, 0, MARGIN, [0; 3], [7; 3], &mut |c| got.push(c));
            got.sort_unstable();
            let len = got.len();
            got.dedup();
            assert_eq!(len, got.len(), "{a:?}-{b:?}: a cell reported twice");
            for x in 0..8u32 {
                for y in 0..8u32 {
                    for z in 0..8u32 {
                        let c = [x, y, z];
                        if near(a, b, c, MARGIN) {
                            assert!(got.binary_search(&c).is_ok(), "{a:?}-{b:?}: {c:?} missing");
                        }
                    }
                }
            }
            for &c in &got {
                assert!(
                    near(a, b, c, 1.0),
                    "{a:?}-{b:?}: {c:?} is far from the segment"
                );
            }
        }
        // Cells of side 4 (as for bricks), clipped to x <= 2: the diagonal (0.25 .. 3.75 cells)
        // passes the cell corners (1, 1), (2, 2), (3, 3), so the closed cells around them count.
        let mut got = Vec::new();
        let (a, b) = ([1.0, 1.0, 1.0], [15.0, 15.0, 1.0]);
        for_segment_cells(a, b, 2, MARGIN, [0; 3], [2, 3, 3], &mut |c| got.push(c));
        got.sort_unstable();
        let want = [
            [0, 0],
            [0, 1],
            [1, 0],
            [1, 1],
            [1, 2],
            [2, 1],
            [2, 2],
            [2, 3],
        ];
        assert_eq!(got, want.map(|[x, y]| [x, y, 0]).to_vec());
    }
}
