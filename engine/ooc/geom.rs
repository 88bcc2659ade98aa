//! Triangles, boxes, the watertight ray/triangle test and a binned-SAH BVH (flattened).
//!
//! Used for both levels: the top-level BVH over the batching points' bounds and each point's
//! bottom-level BVH over its triangles. Every function is deterministic (same input, same
//! nodes, same f32 operations), which the in-core/out-of-core equality relies on.

// Per-axis index loops over several arrays at once read clearer than zipped iterators.
#![allow(clippy::needless_range_loop)]

/// A triangle as three vertices (world space, f32).
pub type Tri = [[f32; 3]; 3];

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Minimum corner.
    pub lo: [f32; 3],
    /// Maximum corner.
    pub hi: [f32; 3],
}

impl Aabb {
    /// The empty box (grows from nothing).
    pub const EMPTY: Aabb = Aabb {
        lo: [f32::INFINITY; 3],
        hi: [f32::NEG_INFINITY; 3],
    };

    /// Grows the box to hold `p`.
    #[inline]
    pub fn grow(&mut self, p: [f32; 3]) {
        for k in 0..3 {
            self.lo[k] = self.lo[k].min(p[k]);
            self.hi[k] = self.hi[k].max(p[k]);
        }
    }

    /// Grows the box to hold `b`.
    #[inline]
    pub fn union(&mut self, b: &Aabb) {
        for k in 0..3 {
            self.lo[k] = self.lo[k].min(b.lo[k]);
            self.hi[k] = self.hi[k].max(b.hi[k]);
        }
    }

    /// Bounds of a triangle.
    pub fn of_tri(t: &Tri) -> Aabb {
        let mut b = Aabb::EMPTY;
        for v in t {
            b.grow(*v);
        }
        b
    }

    /// Half the surface area (the SAH only compares areas); 0 for an empty box.
    fn half_area(&self) -> f32 {
        let d = [
            (self.hi[0] - self.lo[0]).max(0.0),
            (self.hi[1] - self.lo[1]).max(0.0),
            (self.hi[2] - self.lo[2]).max(0.0),
        ];
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }

    /// Centre of the box.
    pub fn center(&self) -> [f32; 3] {
        [
            0.5 * (self.lo[0] + self.hi[0]),
            0.5 * (self.lo[1] + self.hi[1]),
            0.5 * (self.lo[2] + self.hi[2]),
        ]
    }
}

/// A ray with its precomputed constants for box and watertight triangle tests.
#[derive(Clone, Copy, Debug)]
pub struct RayPre {
    /// Origin.
    pub origin: [f32; 3],
    /// Direction (need not be normalised).
    pub dir: [f32; 3],
    inv: [f32; 3],
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

/// Inverse for a zero direction component (finite, so `0 * inv` is never NaN).
const PARALLEL_INV: f32 = 1e36;

impl RayPre {
    /// Precomputes the slab inverses and the watertight shear of a ray.
    pub fn new(origin: [f32; 3], dir: [f32; 3]) -> RayPre {
        let inv = dir.map(|d| if d == 0.0 { PARALLEL_INV } else { 1.0 / d });
        let a = dir.map(f32::abs);
        let kz = if a[0] >= a[1] && a[0] >= a[2] {
            0
        } else if a[1] >= a[2] {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        RayPre {
            origin,
            dir,
            inv,
            kx,
            ky,
            kz,
            sx: dir[kx] / dir[kz],
            sy: dir[ky] / dir[kz],
            sz: 1.0 / dir[kz],
        }
    }

    /// Slab test: `(t_enter, t_exit)` with `t_enter = max(t_near, 0)`; the box is hit when
    /// `t_enter <= t_exit` (closed, so a ray grazing a flat box still enters it).
    #[inline]
    pub fn slab(&self, b: &Aabb) -> (f32, f32) {
        let mut t0 = 0.0f32;
        let mut t1 = f32::INFINITY;
        for k in 0..3 {
            let a = (b.lo[k] - self.origin[k]) * self.inv[k];
            let c = (b.hi[k] - self.origin[k]) * self.inv[k];
            t0 = t0.max(a.min(c));
            t1 = t1.min(a.max(c));
        }
        (t0, t1)
    }

    /// Watertight ray/triangle test (Woop, Benthin and Wald 2013): the hit distance `t > 0`,
    /// or `None`. Edge functions that come out exactly zero are recomputed in f64, so a ray
    /// through a shared edge hits at least one of the two triangles.
    #[inline]
    pub fn intersect(&self, tri: &Tri) -> Option<f32> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = sub(tri[0], self.origin);
        let b = sub(tri[1], self.origin);
        let c = sub(tri[2], self.origin);
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        if u == 0.0 || v == 0.0 || w == 0.0 {
            u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
            v = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
            w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t_scaled = u * az + v * bz + w * cz;
        if (det > 0.0 && t_scaled <= 0.0) || (det < 0.0 && t_scaled >= 0.0) {
            return None;
        }
        let t = t_scaled / det;
        (t > 0.0 && t.is_finite()).then_some(t)
    }
}

#[inline]
fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Unit geometric normal of a triangle facing against `dir` (zero for degenerate triangles).
pub fn facing_normal(tri: &Tri, dir: [f32; 3]) -> [f32; 3] {
    let e1 = sub(tri[1], tri[0]);
    let e2 = sub(tri[2], tri[0]);
    let n = [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len == 0.0 || !len.is_finite() {
        return [0.0; 3];
    }
    let s = if n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2] > 0.0 {
        -1.0 / len
    } else {
        1.0 / len
    };
    [n[0] * s, n[1] * s, n[2] * s]
}

/// A flattened BVH node: a leaf when `count > 0` (primitives `first..first + count` of the
/// BVH's order), else an inner node whose children are nodes `first` and `first + 1`.
#[derive(Clone, Copy, Debug)]
pub struct Node {
    /// Bounds of everything below.
    pub bounds: Aabb,
    /// First primitive (leaf) or left child (inner).
    pub first: u32,
    /// Primitive count (leaf) or 0 (inner).
    pub count: u32,
}

/// A BVH over primitives given by their boxes; `order[i]` is the input index of the i-th leaf
/// primitive.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    /// Nodes, root at 0.
    pub nodes: Vec<Node>,
    /// Primitive permutation.
    pub order: Vec<u32>,
}

/// SAH bins per axis.
const BINS: usize = 16;
/// Largest leaf.
const MAX_LEAF: usize = 8;

impl Bvh {
    /// Builds a binned-SAH BVH (16 bins on centroids, leaves of at most 8 primitives).
    pub fn build(boxes: &[Aabb]) -> Bvh {
        if boxes.is_empty() {
            return Bvh::default();
        }
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(2 * boxes.len() / 2 + 1),
            order: (0..boxes.len() as u32).collect(),
        };
        let centers: Vec<[f32; 3]> = boxes.iter().map(Aabb::center).collect();
        let mut root = Aabb::EMPTY;
        for b in boxes {
            root.union(b);
        }
        bvh.nodes.push(Node {
            bounds: root,
            first: 0,
            count: boxes.len() as u32,
        });
        // Explicit stack: (node index, start, end).
        let mut stack = vec![(0usize, 0usize, boxes.len())];
        while let Some((node, start, end)) = stack.pop() {
            let Some(mid) = split(boxes, &centers, &mut bvh.order[start..end]) else {
                continue;
            };
            let mid = start + mid;
            let left = bvh.nodes.len();
            for (s, e) in [(start, mid), (mid, end)] {
                let mut b = Aabb::EMPTY;
                for &i in &bvh.order[s..e] {
                    b.union(&boxes[i as usize]);
                }
                bvh.nodes.push(Node {
                    bounds: b,
                    first: s as u32,
                    count: (e - s) as u32,
                });
            }
            bvh.nodes[node].first = left as u32;
            bvh.nodes[node].count = 0;
            stack.push((left + 1, mid, end));
            stack.push((left, start, mid));
        }
        bvh
    }

    /// Bytes of the nodes and the permutation.
    pub fn bytes(&self) -> u64 {
        (self.nodes.len() * std::mem::size_of::<Node>() + self.order.len() * 4) as u64
    }
}

/// Chooses a binned-SAH split of `order` (reordering it): the size of the left part, or `None`
/// when a leaf is cheaper (or the primitives cannot be separated).
fn split(boxes: &[Aabb], centers: &[[f32; 3]], order: &mut [u32]) -> Option<usize> {
    let n = order.len();
    if n <= 2 {
        return None;
    }
    let mut cb = Aabb::EMPTY;
    let mut nb = Aabb::EMPTY;
    for &i in order.iter() {
        cb.grow(centers[i as usize]);
        nb.union(&boxes[i as usize]);
    }
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, bin)
    for axis in 0..3 {
        let (lo, hi) = (cb.lo[axis], cb.hi[axis]);
        if hi <= lo {
            continue;
        }
        let scale = BINS as f32 / (hi - lo);
        let mut bins = [(Aabb::EMPTY, 0usize); BINS];
        for &i in order.iter() {
            let b = (((centers[i as usize][axis] - lo) * scale) as usize).min(BINS - 1);
            bins[b].0.union(&boxes[i as usize]);
            bins[b].1 += 1;
        }
        let mut right_area = [0f32; BINS];
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        let mut right_cnt = [0usize; BINS];
        for b in (1..BINS).rev() {
            acc.union(&bins[b].0);
            cnt += bins[b].1;
            right_area[b] = acc.half_area();
            right_cnt[b] = cnt;
        }
        let mut acc = Aabb::EMPTY;
        let mut cnt = 0;
        for b in 0..BINS - 1 {
            acc.union(&bins[b].0);
            cnt += bins[b].1;
            if cnt == 0 || right_cnt[b + 1] == 0 {
                continue;
            }
            let cost = acc.half_area() * cnt as f32 + right_area[b + 1] * right_cnt[b + 1] as f32;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, b));
            }
        }
    }
    let leaf_cost = nb.half_area() * n as f32;
    let Some((cost, axis, bin)) = best else {
        // All centroids coincide: split in the middle when the leaf would be too large.
        return (n > MAX_LEAF).then_some(n / 2);
    };
    if n <= MAX_LEAF && cost + nb.half_area() >= leaf_cost {
        return None;
    }
    let (lo, hi) = (cb.lo[axis], cb.hi[axis]);
    let scale = BINS as f32 / (hi - lo);
    let is_left =
        |i: u32| (((centers[i as usize][axis] - lo) * scale) as usize).min(BINS - 1) <= bin;
    // Stable partition keeps the build deterministic and independent of sort internals.
    let (left, right): (Vec<u32>, Vec<u32>) = order.iter().partition(|&&i| is_left(i));
    let mid = left.len();
    order[..mid].copy_from_slice(&left);
    order[mid..].copy_from_slice(&right);
    Some(mid)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn watertight_shared_edge_is_hit_once_or_twice() {
        // Two triangles sharing the diagonal of the unit square; a ray straight through it.
        let a: Tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]];
        let b: Tri = [[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let r = RayPre::new([0.5, 0.5, -1.0], [0.0, 0.0, 1.0]);
        assert!(r.intersect(&a).is_some() || r.intersect(&b).is_some());
        let miss = RayPre::new([2.0, 0.5, -1.0], [0.0, 0.0, 1.0]);
        assert!(miss.intersect(&a).is_none() && miss.intersect(&b).is_none());
        assert_eq!(r.intersect(&a).or(r.intersect(&b)), Some(1.0));
    }

    #[test]
    fn bvh_covers_every_primitive() {
        let boxes: Vec<Aabb> = (0..1000)
            .map(|i| {
                let x = ((i * 37) % 101) as f32;
                let y = ((i * 53) % 97) as f32;
                Aabb {
                    lo: [x, y, 0.0],
                    hi: [x + 1.0, y + 1.0, 1.0],
                }
            })
            .collect();
        let bvh = Bvh::build(&boxes);
        let mut seen = vec![0; boxes.len()];
        for n in bvh.nodes.iter().filter(|n| n.count > 0) {
            for &p in &bvh.order[n.first as usize..(n.first + n.count) as usize] {
                seen[p as usize] += 1;
                let b = &boxes[p as usize];
                assert!((0..3).all(|k| n.bounds.lo[k] <= b.lo[k] && b.hi[k] <= n.bounds.hi[k]));
            }
        }
        assert!(seen.iter().all(|&s| s == 1));
    }
}
