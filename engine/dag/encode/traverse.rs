//! Traversal of encoded DAGs through one small interface, [`TreeView`]: point lookup, voxel
//! enumeration in Morton order, ray casting and conversion back to an SVDAG.
//!
//! A view hands out node handles; `children` returns the 8 children of a node in *world*
//! octant order (`x | y << 1 | z << 2` of the grid, after the node's transform, translation or
//! mirror has been applied), so the algorithms here never see transforms.

// Per-axis index loops mirror the GLSL vector code one to one.
#![allow(clippy::needless_range_loop)]

use super::{DigestBuilder, EncodeError, VoxelDigest};
use crate::dag::raycast::{hit_normal, Ray, RaySetup, MAX_FRAMES};
use crate::dag::Svdag;
use crate::scene::{morton, Voxels};

/// Read access to an encoded DAG, node by node.
pub trait TreeView {
    /// A handle to a node (with whatever transform state reaching it needs).
    type Node: Clone;
    /// Grid side length (power of two, at least 8).
    fn resolution(&self) -> u32;
    /// The root node (level `log2(N) - 2`), `None` for an empty scene.
    fn root(&self) -> Result<Option<Self::Node>, EncodeError>;
    /// Children of an inner node at `level >= 1`, by world octant.
    fn children(
        &self,
        node: &Self::Node,
        level: u32,
    ) -> Result<[Option<Self::Node>; 8], EncodeError>;
    /// The 64-bit mask (bit `morton(x, y, z)`) of a level-0 node, in world orientation.
    fn leaf(&self, node: &Self::Node) -> Result<u64, EncodeError>;
    /// The handle as one 64-bit value, when it fits: distinct handles of a level give distinct
    /// values. Memoized walks (the content digest) then keep 8-byte keys per handle.
    fn packed(&self, _node: &Self::Node) -> Option<u64> {
        None
    }
}

/// Level of the root of a grid of side `n`.
pub(crate) fn root_level(n: u32) -> u32 {
    n.trailing_zeros() - 2
}

/// Whether voxel (x, y, z) is set (false outside the grid), walking `view` from the root.
pub fn contains<V: TreeView>(view: &V, x: u32, y: u32, z: u32) -> Result<bool, EncodeError> {
    let n = view.resolution();
    if x >= n || y >= n || z >= n {
        return Ok(false);
    }
    let Some(mut node) = view.root()? else {
        return Ok(false);
    };
    for level in (1..=root_level(n)).rev() {
        let bit = level + 1;
        let o = ((x >> bit) & 1) | ((y >> bit) & 1) << 1 | ((z >> bit) & 1) << 2;
        match view.children(&node, level)?[o as usize].take() {
            Some(child) => node = child,
            None => return Ok(false),
        }
    }
    Ok(view.leaf(&node)? >> morton::encode(x & 3, y & 3, z & 3) & 1 == 1)
}

/// One inner node being enumerated.
struct Frame<N> {
    children: [Option<N>; 8],
    next: u8,
    prefix: u64,
}

/// Iterates the Morton codes of all set voxels in ascending order, reading the encoded DAG.
/// Stops after the first error (which it yields).
pub struct VoxelIter<'a, V: TreeView> {
    view: &'a V,
    stack: Vec<Frame<V::Node>>,
    leaf_prefix: u64,
    leaf_mask: u64,
    root_level: u32,
    started: bool,
    failed: bool,
}

impl<'a, V: TreeView> VoxelIter<'a, V> {
    /// A new iterator over `view`.
    pub fn new(view: &'a V) -> Self {
        VoxelIter {
            view,
            stack: Vec::new(),
            leaf_prefix: 0,
            leaf_mask: 0,
            root_level: root_level(view.resolution()),
            started: false,
            failed: false,
        }
    }

    fn step(&mut self) -> Result<Option<u64>, EncodeError> {
        if !self.started {
            self.started = true;
            if let Some(root) = self.view.root()? {
                let children = self.view.children(&root, self.root_level)?;
                self.stack.push(Frame {
                    children,
                    next: 0,
                    prefix: 0,
                });
            }
        }
        loop {
            if self.leaf_mask != 0 {
                let bit = self.leaf_mask.trailing_zeros() as u64;
                self.leaf_mask &= self.leaf_mask - 1;
                return Ok(Some(self.leaf_prefix << 6 | bit));
            }
            let depth = self.stack.len();
            let Some(top) = self.stack.last_mut() else {
                return Ok(None);
            };
            if top.next == 8 {
                self.stack.pop();
                continue;
            }
            let o = top.next;
            top.next += 1;
            let Some(child) = top.children[o as usize].take() else {
                continue;
            };
            let prefix = top.prefix << 3 | o as u64;
            // The frame at depth d (1-based) is a node of level root_level + 1 - d.
            let child_level = self.root_level - depth as u32;
            if child_level == 0 {
                self.leaf_mask = self.view.leaf(&child)?;
                self.leaf_prefix = prefix;
            } else {
                let children = self.view.children(&child, child_level)?;
                self.stack.push(Frame {
                    children,
                    next: 0,
                    prefix,
                });
            }
        }
    }
}

impl<V: TreeView> Iterator for VoxelIter<'_, V> {
    type Item = Result<u64, EncodeError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.failed {
            return None;
        }
        match self.step() {
            Ok(code) => code.map(Ok),
            Err(e) => {
                self.failed = true;
                Some(Err(e))
            }
        }
    }
}

/// Voxel count and checksum of everything `view` holds.
pub fn voxel_digest<V: TreeView>(view: &V) -> Result<VoxelDigest, EncodeError> {
    let mut d = DigestBuilder::default();
    for code in VoxelIter::new(view) {
        d.push(code?);
    }
    Ok(d.finish())
}

/// Decodes `view` to an SVDAG with the given colours (one per voxel, Morton order, or none).
pub fn to_svdag<V: TreeView>(view: &V, colors: Vec<u32>) -> Result<Svdag, EncodeError> {
    let codes = VoxelIter::new(view).collect::<Result<Vec<u64>, _>>()?;
    let voxels = Voxels {
        resolution: view.resolution(),
        codes,
        colors,
    };
    Svdag::from_voxels(&voxels).map_err(|e| EncodeError::InvalidInput(e.to_string()))
}

/// The first voxel a ray enters (same conventions and f32 operations as
/// [`Svdag::raycast`](crate::dag::Svdag::raycast), without the colour index).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EncodedHit {
    /// Ray parameter of the entry point.
    pub t: f32,
    /// The voxel hit.
    pub voxel: [u32; 3],
    /// Axis-aligned normal of the entry face, pointing against the ray.
    pub normal: [i32; 3],
}

/// What a ray-cast frame holds: an inner node's children, or the 64-bit mask of a leaf (whose
/// "children" are its eight 2^3 sub-blocks), or one 2^3 sub-block.
enum RayFrame<N> {
    Inner([Option<N>; 8]),
    Leaf(u64),
    Block(u8),
}

impl<N> RayFrame<N> {
    fn has(&self, c: u32) -> bool {
        match self {
            RayFrame::Inner(ch) => ch[c as usize].is_some(),
            RayFrame::Leaf(m) => (m >> (8 * c)) & 0xff != 0,
            RayFrame::Block(b) => (b >> c) & 1 == 1,
        }
    }
}

/// Casts a ray through `view` front to back: the first set voxel entered at `t` in `[0, t_max)`.
pub fn raycast<V: TreeView>(
    view: &V,
    ray: &Ray,
    t_max: f32,
) -> Result<Option<EncodedHit>, EncodeError> {
    let finite = ray
        .origin
        .iter()
        .chain(ray.dir.iter())
        .all(|v| v.is_finite());
    if !finite || ray.dir == [0.0; 3] {
        return Ok(None);
    }
    let n = view.resolution();
    let root_lvl = root_level(n) as usize;
    let voxel_depth = root_lvl + 2;
    if voxel_depth > MAX_FRAMES {
        return Ok(None);
    }
    let Some(root) = view.root()? else {
        return Ok(None);
    };
    let setup = RaySetup::new(ray);
    let (t_near, t_far, _) = setup.slab([0; 3], n);
    let t_enter = t_near.max(0.0);
    if !(t_enter < t_far && t_enter < t_max) {
        return Ok(None);
    }
    let mut stack: Vec<(RayFrame<V::Node>, u32)> = Vec::with_capacity(voxel_depth);
    stack.push((RayFrame::Inner(view.children(&root, root_lvl as u32)?), 0));
    let mut cursor = [0u32; 3];
    loop {
        let depth = stack.len() - 1;
        let top = stack.last_mut().expect("stack is never empty here");
        let next = top.1;
        if next == 8 {
            if depth == 0 {
                return Ok(None);
            }
            stack.pop();
            continue;
        }
        top.1 += 1;
        let c = next ^ setup.mirror;
        if !top.0.has(c) {
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
            return Ok(Some(EncodedHit {
                t: t_enter,
                voxel: child,
                normal: hit_normal(ray.dir, t_near, axis),
            }));
        }
        let frame = match &mut top.0 {
            RayFrame::Inner(children) => {
                let node = children[c as usize].clone().expect("checked by has()");
                let child_level = (root_lvl - depth - 1) as u32;
                if child_level == 0 {
                    RayFrame::Leaf(view.leaf(&node)?)
                } else {
                    RayFrame::Inner(view.children(&node, child_level)?)
                }
            }
            RayFrame::Leaf(m) => RayFrame::Block(((*m >> (8 * c)) & 0xff) as u8),
            RayFrame::Block(_) => unreachable!("voxel depth returns above"),
        };
        stack.push((frame, 0));
    }
}

/// The plain SVDAG as a view (node handle = word offset); the reference for the other views.
impl TreeView for Svdag {
    type Node = usize;

    fn resolution(&self) -> u32 {
        self.resolution
    }

    fn root(&self) -> Result<Option<usize>, EncodeError> {
        Ok((self.words.first().copied().unwrap_or(0) != 0).then_some(0))
    }

    fn children(&self, node: &usize, _level: u32) -> Result<[Option<usize>; 8], EncodeError> {
        let mask = *self
            .words
            .get(*node)
            .ok_or_else(|| super::corrupt(*node as u64 * 4, "node offset out of range"))?;
        let mut out = [None; 8];
        let mut k = 0;
        for (o, slot) in out.iter_mut().enumerate() {
            if (mask >> o) & 1 == 1 {
                let p = *self.words.get(node + 1 + k).ok_or_else(|| {
                    super::corrupt((node + 1 + k) as u64 * 4, "pointer out of range")
                })?;
                *slot = Some(p as usize);
                k += 1;
            }
        }
        Ok(out)
    }

    fn leaf(&self, node: &usize) -> Result<u64, EncodeError> {
        if node + 1 >= self.words.len() {
            return Err(super::corrupt(*node as u64 * 4, "leaf out of range"));
        }
        Ok(self.leaf_mask(*node))
    }

    fn packed(&self, node: &usize) -> Option<u64> {
        Some(*node as u64)
    }
}

/// An axis-aligned box `(min, max)` in grid coordinates (max exclusive).
pub type Bounds = ([u32; 3], [u32; 3]);

/// Bounding box `(min, max)` of the occupied nodes `root_level - 6` levels down (the same
/// coarse boxes as `Svdag::occupied_bounds`, so cameras framed from either agree), read from
/// the encoded DAG; `None` for an empty scene.
pub fn occupied_bounds<V: TreeView>(view: &V) -> Result<Option<Bounds>, EncodeError> {
    let top = root_level(view.resolution());
    let stop_level = top.saturating_sub(6);
    let Some(root) = view.root()? else {
        return Ok(None);
    };
    let mut min = [u32::MAX; 3];
    let mut max = [0u32; 3];
    let mut stack = vec![(root, top, [0u32; 3])];
    while let Some((node, level, corner)) = stack.pop() {
        let size = 4u32 << level;
        if level == stop_level {
            for a in 0..3 {
                min[a] = min[a].min(corner[a]);
                max[a] = max[a].max(corner[a] + size);
            }
            continue;
        }
        let half = size / 2;
        for (octant, child) in view.children(&node, level)?.into_iter().enumerate() {
            if let Some(child) = child {
                let o = octant as u32;
                let offset = [o & 1, (o >> 1) & 1, o >> 2];
                stack.push((
                    child,
                    level - 1,
                    [0, 1, 2].map(|a| corner[a] + offset[a] * half),
                ));
            }
        }
    }
    Ok((min[0] != u32::MAX).then_some((min, max)))
}
