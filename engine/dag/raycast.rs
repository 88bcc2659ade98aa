//! CPU ray cast through an SVDAG (the reference for `shaders/glsl/render/traverse.glsl`).
//!
//! Conventions (see `docs/rendering.md`):
//! - Rays live in grid coordinates: voxel `(x, y, z)` is the cube `[x, x+1] x [y, y+1] x [z, z+1]`,
//!   the grid is `[0, N)^3`. `dir` need not be normalised; `t` is measured in units of `dir`.
//! - A hit is the first occupied voxel whose box the ray enters at `t` in `[0, t_max)`.
//!   The entry is `max(t_near, 0)`: a ray that starts inside an occupied voxel hits it at `t = 0`
//!   and gets the normal of its dominant axis, pointing against the ray.
//! - A box is entered when `max(t_near, 0) < t_far` (strict), so a ray that only grazes an edge
//!   or corner (`t_near == t_far`) misses that box.
//! - Directions with a zero component use the inverse `PARALLEL_INV = 1e36` (never NaN: a zero
//!   distance gives `t = 0`), and unbounded rays use `t_max = T_UNBOUNDED = 1e30`. A ray on a
//!   slab's low plane counts as inside it, on its high plane as outside (half-open cells).
//!
//! The traversal is a stack of frames, one per depth: depth 0 is the root, depth
//! `root_level` is a 4^3 leaf, depth `root_level + 1` a 2^3 sub-block of a leaf and depth
//! `root_level + 2` a voxel. Each frame holds its node word offset and `mask | next << 8`, where
//! `mask` is its 8-bit child mask and `next` the next ordinal `i` in `0..8`; the child visited is
//! octant `i ^ mirror` (mirror bit `k` set where `dir[k] < 0`), which is front to back along the
//! ray. The position of a frame's cube is not stored: it is the cursor (the last child entered)
//! with its low bits cleared. Every step is written so that the GLSL twin can perform the same
//! f32 operations in the same order.

// Per-axis index loops mirror the GLSL vector code one to one.
#![allow(clippy::needless_range_loop)]

use super::{Svdag, VoxelIndex};
use crate::scene::{morton, Voxels};

/// Inverse used for a zero direction component: a ray parallel to a slab at distance `d >= 1e-6`
/// outside it gets a near `t >= d * 1e36 >= T_UNBOUNDED`, so it never enters.
pub const PARALLEL_INV: f32 = 1e36;

/// The `t_max` of rays without a bound (primary and shadow rays, CPU and GPU).
pub const T_UNBOUNDED: f32 = 1e30;

/// Frames the CPU traversal can hold: grids up to `2^(MAX_FRAMES)` voxels per side.
pub const MAX_FRAMES: usize = 24;

/// A ray in grid coordinates (`dir` need not be normalised).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: [f32; 3],
    /// Direction (non-zero).
    pub dir: [f32; 3],
}

/// The first voxel a ray enters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the entry point (`origin + t * dir`), `>= 0`.
    pub t: f32,
    /// Coordinates of the voxel hit.
    pub voxel: [u32; 3],
    /// Axis-aligned normal of the entry face, pointing against the ray.
    pub normal: [i32; 3],
    /// Index of the voxel in the depth-first Morton order (index into `Svdag::colors`).
    pub color_index: u64,
}

/// Per-ray constants shared by every box test (also used by the traversal of encoded DAGs).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RaySetup {
    origin: [f32; 3],
    inv: [f32; 3],
    /// Bit `k` set when the ray goes towards -k: the child visit order is `i ^ mirror`.
    pub(crate) mirror: u32,
}

impl RaySetup {
    /// `1/dir` (a huge finite value for zero components) and the mirror mask of a ray.
    pub(crate) fn new(ray: &Ray) -> RaySetup {
        let mut inv = [0.0f32; 3];
        let mut mirror = 0u32;
        for k in 0..3 {
            inv[k] = if ray.dir[k] == 0.0 {
                PARALLEL_INV
            } else {
                1.0 / ray.dir[k]
            };
            if ray.dir[k] < 0.0 {
                mirror |= 1 << k;
            }
        }
        RaySetup {
            origin: ray.origin,
            inv,
            mirror,
        }
    }

    /// Slab test of the cube `[pos, pos + size]^3`: `(t_near, t_far, axis of t_near)`.
    ///
    /// The near plane of axis `k` is the low one unless mirror bit `k` is set; `t_near` is the
    /// maximum over x, y, z (ties keep the earlier axis), `t_far` the minimum.
    #[inline]
    pub(crate) fn slab(&self, pos: [u32; 3], size: u32) -> (f32, f32, usize) {
        let mut near = [0.0f32; 3];
        let mut far = [0.0f32; 3];
        for k in 0..3 {
            let lo = (pos[k] as f32 - self.origin[k]) * self.inv[k];
            let hi = ((pos[k] + size) as f32 - self.origin[k]) * self.inv[k];
            if self.mirror & (1 << k) != 0 {
                near[k] = hi;
                far[k] = lo;
            } else {
                near[k] = lo;
                far[k] = hi;
            }
        }
        let axis = if near[0] >= near[1] && near[0] >= near[2] {
            0
        } else if near[1] >= near[2] {
            1
        } else {
            2
        };
        let t_near = near[0].max(near[1]).max(near[2]);
        let t_far = far[0].min(far[1]).min(far[2]);
        (t_near, t_far, axis)
    }
}

/// Face normal of a hit: the entry axis, or the dominant direction axis when `t_near < 0`
/// (the ray starts inside the voxel). Points against the ray.
pub(crate) fn hit_normal(dir: [f32; 3], t_near: f32, entry_axis: usize) -> [i32; 3] {
    let axis = if t_near < 0.0 {
        let a = [dir[0].abs(), dir[1].abs(), dir[2].abs()];
        if a[0] >= a[1] && a[0] >= a[2] {
            0
        } else if a[1] >= a[2] {
            1
        } else {
            2
        }
    } else {
        entry_axis
    };
    let mut normal = [0i32; 3];
    normal[axis] = if dir[axis] > 0.0 { -1 } else { 1 };
    normal
}

/// 8-bit mask of the non-empty 2^3 sub-blocks of a leaf (bit `s` = byte `s` of the mask is set).
#[inline]
fn leaf_block_mask(leaf: u64) -> u32 {
    let mut mask = 0;
    for s in 0..8 {
        if (leaf >> (8 * s)) & 0xff != 0 {
            mask |= 1 << s;
        }
    }
    mask
}

impl Svdag {
    /// Casts a ray: the first occupied voxel entered at `t` in `[0, t_max)`, with its colour index.
    ///
    /// Returns `None` for misses, for non-finite rays and for DAGs too deep for the stack.
    pub fn raycast(&self, index: &VoxelIndex, ray: &Ray, t_max: f32) -> Option<Hit> {
        let finite = ray
            .origin
            .iter()
            .chain(ray.dir.iter())
            .all(|v| v.is_finite());
        if !finite || ray.dir == [0.0; 3] || self.words.is_empty() {
            return None;
        }
        let n = self.resolution;
        if !n.is_power_of_two() || n < 8 {
            return None;
        }
        let root_level = self.root_level();
        let voxel_depth = root_level as usize + 2;
        if voxel_depth > MAX_FRAMES {
            return None;
        }
        let setup = RaySetup::new(ray);
        let (t_near, t_far, _) = setup.slab([0; 3], n);
        let t_enter = t_near.max(0.0);
        if !(t_enter < t_far && t_enter < t_max) {
            return None;
        }
        // stack[d] = (node word offset, child mask | next ordinal << 8).
        let mut stack = [(0u32, 0u32); MAX_FRAMES];
        stack[0] = (0, self.words[0] & 0xff);
        let mut depth = 0usize;
        let mut cursor = [0u32; 3];
        loop {
            let (node, state) = stack[depth];
            let next = state >> 8;
            if next == 8 {
                if depth == 0 {
                    return None;
                }
                depth -= 1;
                continue;
            }
            stack[depth].1 = state + 256;
            let c = next ^ setup.mirror;
            if state & (1 << c) == 0 {
                continue;
            }
            let size = n >> depth;
            let half = size >> 1;
            let mut child = [0u32; 3];
            for k in 0..3 {
                child[k] = (cursor[k] & !(size - 1)) + ((c >> k) & 1) * half;
            }
            let (t_near, t_far, axis) = setup.slab(child, half);
            let t_enter = t_near.max(0.0);
            if !(t_enter < t_far && t_enter < t_max) {
                continue;
            }
            cursor = child;
            if depth + 1 == voxel_depth {
                return Some(Hit {
                    t: t_enter,
                    voxel: child,
                    normal: hit_normal(ray.dir, t_near, axis),
                    color_index: self.path_color_index(index, &stack[..=depth], setup.mirror),
                });
            }
            let leaf_depth = root_level as usize;
            let pushed = if depth + 1 < leaf_depth {
                // Inner child: follow the pointer of octant c.
                let rank = (state & 0xff & ((1 << c) - 1)).count_ones();
                let ptr = self.words[(node + 1 + rank) as usize];
                (ptr, self.words[ptr as usize] & 0xff)
            } else if depth + 1 == leaf_depth {
                // Leaf child: its sub-block occupancy.
                let rank = (state & 0xff & ((1 << c) - 1)).count_ones();
                let ptr = self.words[(node + 1 + rank) as usize];
                (ptr, leaf_block_mask(self.leaf_mask(ptr as usize)))
            } else {
                // Sub-block c of the leaf at `node`: byte c of its mask.
                (
                    node,
                    ((self.leaf_mask(node as usize) >> (8 * c)) & 0xff) as u32,
                )
            };
            depth += 1;
            stack[depth] = pushed;
        }
    }

    /// Colour index of the voxel reached through `frames` (root to sub-block; the child being
    /// visited in each frame is ordinal `next - 1`).
    fn path_color_index(&self, index: &VoxelIndex, frames: &[(u32, u32)], mirror: u32) -> u64 {
        let leaf_depth = self.root_level() as usize;
        let mut color = 0u64;
        for (d, &(node, state)) in frames.iter().enumerate().take(leaf_depth) {
            let c = ((state >> 8) - 1) ^ mirror;
            let rank = (state & 0xff & ((1 << c) - 1)).count_ones();
            for k in 0..rank {
                let child = self.words[(node + 1 + k) as usize];
                color += index.node_voxels[child as usize];
            }
            debug_assert!(d < leaf_depth);
        }
        let (leaf, block_state) = frames[leaf_depth];
        let voxel_state = frames[leaf_depth + 1].1;
        let code = ((((block_state >> 8) - 1) ^ mirror) << 3) | (((voxel_state >> 8) - 1) ^ mirror);
        let below = (1u64 << code) - 1;
        color + (self.leaf_mask(leaf as usize) & below).count_ones() as u64
    }
}

/// Brute-force reference: 3D DDA (Amanatides & Woo) in f64 over every voxel of the grid, with a
/// binary-search lookup in `voxels.codes`. Same conventions as [`Svdag::raycast`]; the colour
/// index is the position of the voxel's Morton code. Meant for small test grids.
pub fn raycast_reference(voxels: &Voxels, ray: &Ray, t_max: f32) -> Option<Hit> {
    let n = voxels.resolution as f64;
    let o = ray.origin.map(|v| v as f64);
    let d = ray.dir.map(|v| v as f64);
    if ray.dir == [0.0; 3] {
        return None;
    }
    // Entry into the grid box.
    let mut t0 = f64::NEG_INFINITY;
    let mut t1 = f64::INFINITY;
    let mut entry_axis = 0;
    for k in 0..3 {
        if d[k] == 0.0 {
            if o[k] < 0.0 || o[k] >= n {
                return None;
            }
            continue;
        }
        let (a, b) = ((0.0 - o[k]) / d[k], (n - o[k]) / d[k]);
        let (near, far) = if a < b { (a, b) } else { (b, a) };
        if near > t0 {
            t0 = near;
            entry_axis = k;
        }
        t1 = t1.min(far);
    }
    let t_start = t0.max(0.0);
    if !(t_start < t1 && t_start < t_max as f64) {
        return None;
    }
    // Voxel containing the start point (clamped against rounding at the entry face).
    let p = [0, 1, 2].map(|k| o[k] + t_start * d[k]);
    let mut cell = [0i64; 3];
    for k in 0..3 {
        let mut c = p[k].floor() as i64;
        if t0 > 0.0 && k == entry_axis {
            c = if d[k] > 0.0 {
                0
            } else {
                voxels.resolution as i64 - 1
            };
        }
        cell[k] = c.clamp(0, voxels.resolution as i64 - 1);
    }
    let step = d.map(|v| if v > 0.0 { 1i64 } else { -1 });
    let mut t_next = [f64::INFINITY; 3];
    let mut t_delta = [f64::INFINITY; 3];
    for k in 0..3 {
        if d[k] != 0.0 {
            let boundary = if d[k] > 0.0 { cell[k] + 1 } else { cell[k] } as f64;
            t_next[k] = (boundary - o[k]) / d[k];
            t_delta[k] = 1.0 / d[k].abs();
        }
    }
    // Normal of the current cell's entry face; `None` while inside the start cell.
    let mut normal: Option<[i32; 3]> = if t0 > 0.0 {
        let mut nrm = [0; 3];
        nrm[entry_axis] = if d[entry_axis] > 0.0 { -1 } else { 1 };
        Some(nrm)
    } else {
        None
    };
    let mut t_cell = t_start;
    loop {
        let voxel = [cell[0] as u32, cell[1] as u32, cell[2] as u32];
        let code = morton::encode(voxel[0], voxel[1], voxel[2]);
        if let Ok(pos) = voxels.codes.binary_search(&code) {
            let normal = normal.unwrap_or_else(|| hit_normal(ray.dir, -1.0, 0));
            return Some(Hit {
                t: t_cell as f32,
                voxel,
                normal,
                color_index: pos as u64,
            });
        }
        let k = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
            0
        } else if t_next[1] <= t_next[2] {
            1
        } else {
            2
        };
        t_cell = t_next[k];
        if t_cell >= t_max as f64 {
            return None;
        }
        cell[k] += step[k];
        if cell[k] < 0 || cell[k] >= voxels.resolution as i64 {
            return None;
        }
        t_next[k] += t_delta[k];
        let mut nrm = [0; 3];
        nrm[k] = -step[k] as i32;
        normal = Some(nrm);
    }
}
