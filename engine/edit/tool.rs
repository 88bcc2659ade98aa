//! Edit tools (HashDAG's): their parameters, inclusion rules and per-voxel results, shared by
//! the CPU reference editor, the GPU editing passes and the brute-force test reference.
//!
//! Inclusion rules (`docs/editing.md`), all in `f32` in exactly this operation order (GLSL
//! mirrors them with `precise`, so no fused multiply-add changes a boundary voxel):
//! - a voxel with integer corner `v` has centre `p = v + 0.5` (exact in `f32` below 2^22);
//! - inside a sphere `(c, r)` iff `dx*dx + dy*dy + dz*dz <= r*r` with `d = p - c`;
//! - inside a cube `(c, r)` iff `c - r <= p && p <= c + r` on every axis.
//!
//! Subtree classification ([`Edit::coverage`]) is exact for "inside" (every `f32` operation
//! above is monotone, so the farthest voxel centre decides) and conservative for "outside".

use rustc_hash::FxHashMap;
use thiserror::Error;

use super::item::MATERIAL_COUNT;

/// A voxel position (integer corner) in the scene grid.
pub type Voxel = [u32; 3];

/// Most voxels the fill tool's region may hold (its flood-fill bitmap is one bit per voxel).
pub const MAX_FILL_VOXELS: u64 = 1 << 32;

/// Why a tool cannot be applied.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum ToolError {
    /// A position, radius or matrix entry is NaN or infinite.
    #[error("non-finite tool parameter {0}")]
    NotFinite(&'static str),
    /// Radius not positive.
    #[error("radius {0} is not positive")]
    Radius(f32),
    /// Material id outside `0..16`.
    #[error("material {0} out of range (0..16)")]
    Material(u8),
    /// The copy transform cannot be inverted.
    #[error("copy transform is singular")]
    Singular,
    /// The fill region is too large for its flood-fill bitmap.
    #[error("fill region of {0} voxels is larger than {MAX_FILL_VOXELS}")]
    FillTooLarge(u64),
}

/// The shape of an add / remove tool.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// Ball of voxel centres within `radius` of `center`.
    Sphere,
    /// Axis-aligned cube of voxel centres within `radius` of `center` per axis.
    Cube,
}

/// Parameters of the copy tool (HashDAG's `CopyEditor`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CopyParams {
    /// Anchor of the source (HashDAG `src`).
    pub source: [f32; 3],
    /// Anchor of the destination (HashDAG `dest`): `source` maps onto it.
    pub dest: [f32; 3],
    /// Centre of the copied source cube (HashDAG `location`).
    pub center: [f32; 3],
    /// Half-size of the copied source cube.
    pub radius: f32,
    /// Optional 3x3 transform (rows) applied around the anchors; `None` = identity.
    pub transform: Option<[[f32; 3]; 3]>,
}

/// One edit: a tool with its parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tool {
    /// Make every voxel inside the shape solid with `material` (materials of voxels already
    /// solid inside it are overwritten too).
    Add {
        /// Sphere or cube.
        shape: Shape,
        /// Centre in voxels.
        center: [f32; 3],
        /// Radius (sphere) or half-size (cube) in voxels.
        radius: f32,
        /// Material id (0 in scenes without materials).
        material: u8,
    },
    /// Make every voxel inside the shape empty.
    Remove {
        /// Sphere or cube.
        shape: Shape,
        /// Centre in voxels.
        center: [f32; 3],
        /// Radius (sphere) or half-size (cube) in voxels.
        radius: f32,
    },
    /// Set the material of every solid voxel inside a sphere (geometry unchanged).
    Paint {
        /// Centre in voxels.
        center: [f32; 3],
        /// Radius in voxels.
        radius: f32,
        /// Material id.
        material: u8,
    },
    /// HashDAG's flood fill: starting at the voxel containing `center` (whatever its state),
    /// the voxels reached through empty voxels by 6-neighbour steps inside the cube
    /// `(center, radius)` become solid with `material` (voxels already solid keep theirs).
    Fill {
        /// Centre (the start voxel is `floor(center)`).
        center: [f32; 3],
        /// Half-size of the cube the fill stays in.
        radius: f32,
        /// Material of the new voxels.
        material: u8,
    },
    /// Copy the solid voxels of a source cube onto the empty voxels of the destination
    /// (HashDAG's copy never removes; copied voxels keep their material).
    Copy(CopyParams),
}

/// How a cube of voxels relates to an edit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coverage {
    /// No voxel of the cube changes: keep the subtree.
    Outside,
    /// Every voxel of the cube is inside the tool's region.
    Inside,
    /// Some voxels may change: subdivide.
    Partial,
}

/// Read access to the voxels of the scene before an edit (copy and fill read it).
pub trait VoxelSource: Sync {
    /// Grid side length.
    fn resolution(&self) -> u32;
    /// Material of the voxel if solid, `None` if empty or outside the grid.
    fn voxel(&self, v: Voxel) -> Option<u8>;
}

/// Centre of a voxel along one axis.
#[inline]
fn centre(x: u32) -> f32 {
    x as f32 + 0.5
}

/// Sphere inclusion of one voxel (module docs).
#[inline]
pub fn in_sphere(center: [f32; 3], radius: f32, v: Voxel) -> bool {
    let dx = centre(v[0]) - center[0];
    let dy = centre(v[1]) - center[1];
    let dz = centre(v[2]) - center[2];
    dx * dx + dy * dy + dz * dz <= radius * radius
}

/// Cube inclusion of one voxel (module docs).
#[inline]
pub fn in_cube(center: [f32; 3], radius: f32, v: Voxel) -> bool {
    (0..3).all(|a| {
        let p = centre(v[a]);
        center[a] - radius <= p && p <= center[a] + radius
    })
}

/// Coverage of the voxel cube `[corner, corner + size)` by a sphere.
pub fn sphere_coverage(center: [f32; 3], radius: f32, corner: Voxel, size: u32) -> Coverage {
    let r2 = radius * radius;
    let (mut far, mut near) = (0f32, 0f32);
    for a in 0..3 {
        let lo = centre(corner[a]);
        let hi = centre(corner[a] + size - 1);
        let (dlo, dhi) = (lo - center[a], hi - center[a]);
        far += (dlo * dlo).max(dhi * dhi);
        let nearest = center[a].clamp(lo, hi) - center[a];
        near += nearest * nearest;
    }
    if far <= r2 {
        Coverage::Inside
    } else if near > r2 {
        Coverage::Outside
    } else {
        Coverage::Partial
    }
}

/// Coverage of the voxel cube `[corner, corner + size)` by a cube tool.
pub fn cube_coverage(center: [f32; 3], radius: f32, corner: Voxel, size: u32) -> Coverage {
    let mut inside = true;
    for a in 0..3 {
        let lo = centre(corner[a]);
        let hi = centre(corner[a] + size - 1);
        let (tlo, thi) = (center[a] - radius, center[a] + radius);
        if hi < tlo || lo > thi {
            return Coverage::Outside;
        }
        inside &= tlo <= lo && hi <= thi;
    }
    if inside {
        Coverage::Inside
    } else {
        Coverage::Partial
    }
}

/// Inclusive voxel box `(min, max)` holding every voxel whose centre lies in `[c - r, c + r]`
/// per axis, clipped to the grid; `None` when it misses the grid. (A superset by one voxel
/// where `f32` rounding could matter: callers still apply the exact rule.)
pub fn voxel_box(center: [f32; 3], radius: f32, resolution: u32) -> Option<(Voxel, Voxel)> {
    let mut min = [0; 3];
    let mut max = [0; 3];
    for a in 0..3 {
        let lo = (center[a] as f64 - radius as f64 - 0.5).ceil() - 1.0;
        let hi = (center[a] as f64 + radius as f64 - 0.5).floor() + 1.0;
        if hi < 0.0 || lo > resolution as f64 - 1.0 || lo > hi {
            return None;
        }
        min[a] = lo.max(0.0) as u32;
        max[a] = hi.min(resolution as f64 - 1.0) as u32;
    }
    Some((min, max))
}

/// Inverse of a 3x3 matrix (rows), computed in f64 and rounded once.
fn inverse(m: [[f32; 3]; 3]) -> Option<[[f32; 3]; 3]> {
    let m = m.map(|row| row.map(|x| x as f64));
    let cof =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let det = m[0][0] * cof(1, 2, 1, 2) - m[0][1] * cof(1, 2, 0, 2) + m[0][2] * cof(1, 2, 0, 1);
    if det.abs() < 1e-12 || !det.is_finite() {
        return None;
    }
    let adj = [
        [cof(1, 2, 1, 2), -cof(0, 2, 1, 2), cof(0, 1, 1, 2)],
        [-cof(1, 2, 0, 2), cof(0, 2, 0, 2), -cof(0, 1, 0, 2)],
        [cof(1, 2, 0, 1), -cof(0, 2, 0, 1), cof(0, 1, 0, 1)],
    ];
    Some(adj.map(|row| row.map(|x| (x / det) as f32)))
}

/// `m * v` in `f32`, each row summed left to right.
#[inline]
fn mul(m: &[[f32; 3]; 3], v: [f32; 3]) -> [f32; 3] {
    m.map(|row| row[0] * v[0] + row[1] * v[1] + row[2] * v[2])
}

/// The copy tool with its derived values (destination cube, inverse transform).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CopyRegion {
    /// The tool's parameters.
    pub params: CopyParams,
    /// Inverse of the transform (destination -> source), if any.
    pub inverse: Option<[[f32; 3]; 3]>,
    /// Centre of the destination cube: `dest + T (center - source)`.
    pub dest_center: [f32; 3],
    /// Half-size of the destination cube: `radius * max_row |sum of row|` (HashDAG's
    /// `(T * (1, 1, 1)).abs().largest()`), `radius` without a transform.
    pub dest_radius: f32,
}

impl CopyRegion {
    /// Derives the destination cube and inverse transform.
    pub fn new(params: CopyParams) -> Result<CopyRegion, ToolError> {
        let rel = [0, 1, 2].map(|a| params.center[a] - params.source[a]);
        let (inverse, moved, scale) = match params.transform {
            None => (None, rel, 1.0),
            Some(t) => {
                let inv = inverse(t).ok_or(ToolError::Singular)?;
                let scale = t
                    .iter()
                    .map(|row| (row[0] + row[1] + row[2]).abs())
                    .fold(0f32, f32::max);
                (Some(inv), mul(&t, rel), scale)
            }
        };
        Ok(CopyRegion {
            params,
            inverse,
            dest_center: [0, 1, 2].map(|a| params.dest[a] + moved[a]),
            dest_radius: params.radius * scale,
        })
    }

    /// The source voxel that destination voxel `v` copies (no bounds check against the
    /// source cube): `floor(source + T^-1 (v + 0.5 - dest))`; `None` outside the grid.
    pub fn source_voxel(&self, v: Voxel, resolution: u32) -> Option<Voxel> {
        let mut rel = [0, 1, 2].map(|a| centre(v[a]) - self.params.dest[a]);
        if let Some(inv) = &self.inverse {
            rel = mul(inv, rel);
        }
        let mut out = [0; 3];
        for a in 0..3 {
            let s = (self.params.source[a] + rel[a]).floor();
            if !(s >= 0.0 && s < resolution as f32) {
                return None;
            }
            out[a] = s as u32;
        }
        Some(out)
    }
}

/// The flood-filled voxels of a fill edit: a bitmap over an inclusive box.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FillSet {
    /// Inclusive box of the bitmap.
    min: Voxel,
    /// Side lengths of the bitmap.
    dims: [u32; 3],
    /// One bit per voxel of the box, x fastest.
    bits: Vec<u64>,
    /// Inclusive box of the set bits, `None` when nothing is filled.
    bounds: Option<(Voxel, Voxel)>,
}

impl FillSet {
    /// Runs the flood fill of `Tool::Fill { center, radius }` over `source`.
    pub fn new(
        center: [f32; 3],
        radius: f32,
        source: &dyn VoxelSource,
    ) -> Result<FillSet, ToolError> {
        let n = source.resolution();
        let mut set = FillSet {
            min: [0; 3],
            dims: [0; 3],
            bits: Vec::new(),
            bounds: None,
        };
        let Some((min, max)) = voxel_box(center, radius, n) else {
            return Ok(set);
        };
        let dims = [0, 1, 2].map(|a| max[a] - min[a] + 1);
        let volume = dims.iter().map(|&d| d as u64).product::<u64>();
        if volume > MAX_FILL_VOXELS {
            return Err(ToolError::FillTooLarge(volume));
        }
        set.min = min;
        set.dims = dims;
        set.bits = vec![0; volume.div_ceil(64) as usize];
        let start = center.map(|c| c.floor());
        if start.iter().any(|&s| !(s >= 0.0 && s < n as f32)) {
            return Ok(set);
        }
        let start = start.map(|s| s as u32);
        if !in_cube(center, radius, start) {
            return Ok(set);
        }
        // Depth-first flood; `bits` marks visited voxels (all of which end up solid).
        let mut stack = vec![start];
        set.set(start);
        let (mut lo, mut hi) = (start, start);
        while let Some(p) = stack.pop() {
            for a in 0..3 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
            for (axis, delta) in [(0, -1i64), (0, 1), (1, -1), (1, 1), (2, -1), (2, 1)] {
                let c = p[axis] as i64 + delta;
                if c < 0 || c >= n as i64 {
                    continue;
                }
                let mut q = p;
                q[axis] = c as u32;
                if in_cube(center, radius, q) && !set.contains(q) && source.voxel(q).is_none() {
                    set.set(q);
                    stack.push(q);
                }
            }
        }
        set.bounds = Some((lo, hi));
        Ok(set)
    }

    fn index(&self, v: Voxel) -> Option<u64> {
        let mut index = 0u64;
        for a in (0..3).rev() {
            let d = v[a].checked_sub(self.min[a])?;
            if d >= self.dims[a] {
                return None;
            }
            index = index * self.dims[a] as u64 + d as u64;
        }
        Some(index)
    }

    fn set(&mut self, v: Voxel) {
        let i = self.index(v).expect("inside the box");
        self.bits[(i / 64) as usize] |= 1 << (i % 64);
    }

    /// True when the flood reached `v`.
    pub fn contains(&self, v: Voxel) -> bool {
        self.index(v)
            .is_some_and(|i| self.bits[(i / 64) as usize] >> (i % 64) & 1 == 1)
    }

    /// Inclusive box of the reached voxels; `None` when none.
    pub fn bounds(&self) -> Option<(Voxel, Voxel)> {
        self.bounds
    }
}

/// A tool ready to apply to one scene state: validated, with what it reads from the scene
/// before the edit (the fill's flood, the copy's source) prepared.
pub struct Edit<'a> {
    /// The tool (material normalized: 0 in scenes without materials).
    pub tool: Tool,
    source: &'a dyn VoxelSource,
    fill: Option<FillSet>,
    copy: Option<CopyRegion>,
}

fn finite(values: &[f32], what: &'static str) -> Result<(), ToolError> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(ToolError::NotFinite(what))
    }
}

fn check_radius(radius: f32) -> Result<(), ToolError> {
    finite(&[radius], "radius")?;
    if radius > 0.0 {
        Ok(())
    } else {
        Err(ToolError::Radius(radius))
    }
}

fn check_material(material: u8) -> Result<(), ToolError> {
    if (material as u32) < MATERIAL_COUNT {
        Ok(())
    } else {
        Err(ToolError::Material(material))
    }
}

impl Tool {
    /// Checks the parameters (finite, radius > 0, material < 16, invertible transform).
    pub fn validate(&self) -> Result<(), ToolError> {
        match *self {
            Tool::Add {
                center,
                radius,
                material,
                ..
            }
            | Tool::Paint {
                center,
                radius,
                material,
            }
            | Tool::Fill {
                center,
                radius,
                material,
            } => {
                finite(&center, "center")?;
                check_radius(radius)?;
                check_material(material)
            }
            Tool::Remove { center, radius, .. } => {
                finite(&center, "center")?;
                check_radius(radius)
            }
            Tool::Copy(p) => {
                finite(&p.source, "source")?;
                finite(&p.dest, "dest")?;
                finite(&p.center, "center")?;
                check_radius(p.radius)?;
                if let Some(t) = p.transform {
                    finite(t.as_flattened(), "transform")?;
                }
                CopyRegion::new(p).map(|_| ())
            }
        }
    }

    /// The tool with its material set to 0 (scenes without materials).
    fn without_materials(mut self) -> Tool {
        match &mut self {
            Tool::Add { material, .. }
            | Tool::Paint { material, .. }
            | Tool::Fill { material, .. } => *material = 0,
            Tool::Remove { .. } | Tool::Copy(_) => {}
        }
        self
    }
}

impl<'a> Edit<'a> {
    /// Validates `tool` and prepares it against the scene before the edit.
    pub fn new(
        tool: &Tool,
        source: &'a dyn VoxelSource,
        materials: bool,
    ) -> Result<Edit<'a>, ToolError> {
        tool.validate()?;
        let tool = if materials {
            *tool
        } else {
            tool.without_materials()
        };
        let fill = match tool {
            Tool::Fill { center, radius, .. } => Some(FillSet::new(center, radius, source)?),
            _ => None,
        };
        let copy = match tool {
            Tool::Copy(p) => Some(CopyRegion::new(p)?),
            _ => None,
        };
        Ok(Edit {
            tool,
            source,
            fill,
            copy,
        })
    }

    /// How the voxel cube `[corner, corner + size)` relates to the edit. `Inside` is only
    /// returned by tools with a uniform result there (add, remove, paint).
    pub fn coverage(&self, corner: Voxel, size: u32) -> Coverage {
        match self.tool {
            Tool::Add {
                shape,
                center,
                radius,
                ..
            }
            | Tool::Remove {
                shape,
                center,
                radius,
            } => match shape {
                Shape::Sphere => sphere_coverage(center, radius, corner, size),
                Shape::Cube => cube_coverage(center, radius, corner, size),
            },
            Tool::Paint { center, radius, .. } => sphere_coverage(center, radius, corner, size),
            Tool::Fill { .. } => {
                let bounds = self.fill.as_ref().and_then(FillSet::bounds);
                match bounds {
                    Some((lo, hi))
                        if (0..3).all(|a| corner[a] <= hi[a] && lo[a] < corner[a] + size) =>
                    {
                        Coverage::Partial
                    }
                    _ => Coverage::Outside,
                }
            }
            Tool::Copy(_) => {
                let copy = self.copy.as_ref().expect("prepared");
                match cube_coverage(copy.dest_center, copy.dest_radius, corner, size) {
                    Coverage::Outside => Coverage::Outside,
                    _ => Coverage::Partial,
                }
            }
        }
    }

    /// True when the edit cannot change a uniform cube of this state (`None` = empty,
    /// `Some(m)` = full of material `m`): such cubes are kept without subdividing.
    pub fn keeps_uniform(&self, state: Option<u8>) -> bool {
        match (self.tool, state) {
            (Tool::Remove { .. } | Tool::Paint { .. }, None) => true,
            (Tool::Add { material, .. } | Tool::Paint { material, .. }, Some(m)) => m == material,
            (Tool::Fill { .. } | Tool::Copy(_), Some(_)) => true,
            _ => false,
        }
    }

    /// The new state of voxel `v` whose state before the edit is `old`.
    pub fn voxel(&self, v: Voxel, old: Option<u8>) -> Option<u8> {
        match self.tool {
            Tool::Add {
                shape,
                center,
                radius,
                material,
            } => {
                if inside(shape, center, radius, v) {
                    Some(material)
                } else {
                    old
                }
            }
            Tool::Remove {
                shape,
                center,
                radius,
            } => {
                if inside(shape, center, radius, v) {
                    None
                } else {
                    old
                }
            }
            Tool::Paint {
                center,
                radius,
                material,
            } => match old {
                Some(_) if in_sphere(center, radius, v) => Some(material),
                _ => old,
            },
            Tool::Fill { material, .. } => match old {
                None if self.fill.as_ref().expect("prepared").contains(v) => Some(material),
                _ => old,
            },
            Tool::Copy(p) => {
                if old.is_some() {
                    return old;
                }
                let copy = self.copy.as_ref().expect("prepared");
                if !in_cube(copy.dest_center, copy.dest_radius, v) {
                    return None;
                }
                let s = copy.source_voxel(v, self.source.resolution())?;
                if in_cube(p.center, p.radius, s) {
                    self.source.voxel(s)
                } else {
                    None
                }
            }
        }
    }

    /// Inclusive voxel box outside which nothing changes (clipped to the grid).
    pub fn bounds(&self) -> Option<(Voxel, Voxel)> {
        let n = self.source.resolution();
        match self.tool {
            Tool::Add { center, radius, .. }
            | Tool::Remove { center, radius, .. }
            | Tool::Paint { center, radius, .. } => voxel_box(center, radius, n),
            Tool::Fill { .. } => self.fill.as_ref().and_then(FillSet::bounds),
            Tool::Copy(_) => {
                let copy = self.copy.as_ref().expect("prepared");
                voxel_box(copy.dest_center, copy.dest_radius, n)
            }
        }
    }
}

fn inside(shape: Shape, center: [f32; 3], radius: f32, v: Voxel) -> bool {
    match shape {
        Shape::Sphere => in_sphere(center, radius, v),
        Shape::Cube => in_cube(center, radius, v),
    }
}

/// A plain voxel set (position -> material), the brute-force reference of every editor.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VoxelMap {
    /// Grid side length.
    pub resolution: u32,
    /// Solid voxels and their materials.
    pub voxels: FxHashMap<Voxel, u8>,
}

impl VoxelSource for VoxelMap {
    fn resolution(&self) -> u32 {
        self.resolution
    }
    fn voxel(&self, v: Voxel) -> Option<u8> {
        self.voxels.get(&v).copied()
    }
}

impl VoxelMap {
    /// Applies `tool` voxel by voxel over its bounding box (brute force).
    pub fn apply(&mut self, tool: &Tool, materials: bool) -> Result<(), ToolError> {
        let before = self.clone();
        let edit = Edit::new(tool, &before, materials)?;
        let Some((min, max)) = edit.bounds() else {
            return Ok(());
        };
        for z in min[2]..=max[2] {
            for y in min[1]..=max[1] {
                for x in min[0]..=max[0] {
                    let v = [x, y, z];
                    match edit.voxel(v, before.voxel(v)) {
                        Some(m) => self.voxels.insert(v, m),
                        None => self.voxels.remove(&v),
                    };
                }
            }
        }
        Ok(())
    }

    /// `(Morton code, material)` of every solid voxel, ascending.
    pub fn sorted(&self) -> Vec<(u64, u8)> {
        let mut out: Vec<(u64, u8)> = self
            .voxels
            .iter()
            .map(|(v, &m)| (crate::scene::morton::encode(v[0], v[1], v[2]), m))
            .collect();
        out.sort_unstable();
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sphere_inclusion_uses_voxel_centres() {
        // Centre (0.5, 0.5, 0.5): voxel 0 is at distance 0, voxel (1,0,0) at exactly 1.
        let c = [0.5; 3];
        assert!(in_sphere(c, 1.0, [1, 0, 0]));
        assert!(!in_sphere(c, 0.99, [1, 0, 0]));
        assert!(!in_sphere(c, 1.0, [1, 1, 0]));
        // Centre on a corner: the 8 voxels around (4, 4, 4) are at sqrt(0.75).
        assert!(in_sphere([4.0; 3], 0.8661, [3, 3, 3]));
        assert!(!in_sphere([4.0; 3], 0.866, [3, 3, 3]));
    }

    #[test]
    fn cube_inclusion_is_closed_per_axis() {
        assert!(in_cube([2.0; 3], 1.5, [0, 0, 0]));
        assert!(in_cube([2.0; 3], 1.5, [3, 3, 3]));
        assert!(!in_cube([2.0; 3], 1.49, [3, 3, 3]));
        assert!(!in_cube([2.0; 3], 1.5, [4, 0, 0]));
    }

    #[test]
    fn coverage_agrees_with_every_voxel() {
        let sizes = [1u32, 2, 4, 8];
        let tools = [
            ([5.3f32, 6.0, 4.5], 3.2f32),
            ([8.0; 3], 4.0),
            ([0.0; 3], 9.5),
        ];
        for (center, radius) in tools {
            for &size in &sizes {
                for corner in [[0u32, 0, 0], [4, 4, 4], [8, 0, 8], [2, 6, 4]] {
                    let voxels: Vec<Voxel> = (0..size * size * size)
                        .map(|i| {
                            [
                                corner[0] + i % size,
                                corner[1] + i / size % size,
                                corner[2] + i / size / size,
                            ]
                        })
                        .collect();
                    for (cov, rule) in [
                        (
                            sphere_coverage(center, radius, corner, size),
                            voxels
                                .iter()
                                .map(|&v| in_sphere(center, radius, v))
                                .collect::<Vec<_>>(),
                        ),
                        (
                            cube_coverage(center, radius, corner, size),
                            voxels.iter().map(|&v| in_cube(center, radius, v)).collect(),
                        ),
                    ] {
                        match cov {
                            Coverage::Inside => assert!(rule.iter().all(|&b| b)),
                            Coverage::Outside => assert!(rule.iter().all(|&b| !b)),
                            Coverage::Partial => {}
                        }
                        if rule.iter().all(|&b| b) {
                            assert_eq!(
                                cov,
                                Coverage::Inside,
                                "{center:?} {radius} {corner:?} {size}"
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn fill_floods_empty_voxels_inside_the_cube() {
        // A wall at x = 5 splits a 16^3 scene; a fill at x = 2 stays on its side.
        let mut map = VoxelMap {
            resolution: 16,
            voxels: FxHashMap::default(),
        };
        for y in 0..16 {
            for z in 0..16 {
                map.voxels.insert([5, y, z], 1);
            }
        }
        let tool = Tool::Fill {
            center: [2.5, 8.5, 8.5],
            radius: 7.0,
            material: 3,
        };
        map.apply(&tool, true).unwrap();
        assert_eq!(map.voxel([0, 8, 8]), Some(3));
        assert_eq!(map.voxel([4, 2, 2]), Some(3));
        assert_eq!(map.voxel([5, 2, 2]), Some(1), "wall keeps its material");
        assert_eq!(map.voxel([6, 8, 8]), None, "other side of the wall");
        // Cube of half-size 7 around y = 8.5: voxel centres 1.5..=15.5, so y = 0 stays empty.
        assert_eq!(map.voxel([2, 0, 8]), None);
    }

    #[test]
    fn copy_moves_solid_voxels_onto_empty_ones() {
        let mut map = VoxelMap {
            resolution: 32,
            voxels: FxHashMap::default(),
        };
        map.voxels.insert([2, 2, 2], 7);
        map.voxels.insert([20, 2, 2], 1);
        let copy = |transform| {
            Tool::Copy(CopyParams {
                source: [0.0; 3],
                dest: [16.0, 0.0, 0.0],
                center: [2.0; 3],
                radius: 2.0,
                transform,
            })
        };
        let mut plain = map.clone();
        plain.apply(&copy(None), true).unwrap();
        assert_eq!(plain.voxel([18, 2, 2]), Some(7));
        assert_eq!(plain.voxel([20, 2, 2]), Some(1), "copy never removes");
        // Mirror x: destination voxel 13 + 0.5 - 16 = -2.5 -> source 2.5 -> voxel 2.
        let mut mirrored = map.clone();
        let t = [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        mirrored.apply(&copy(Some(t)), true).unwrap();
        assert_eq!(mirrored.voxel([13, 2, 2]), Some(7));
        assert!(Tool::Copy(CopyParams {
            transform: Some([[0.0; 3]; 3]),
            ..match copy(None) {
                Tool::Copy(p) => p,
                _ => unreachable!(),
            }
        })
        .validate()
        .is_err());
    }

    #[test]
    fn bad_parameters_are_errors() {
        let sphere = |radius, center| Tool::Add {
            shape: Shape::Sphere,
            center,
            radius,
            material: 0,
        };
        assert_eq!(
            sphere(0.0, [1.0; 3]).validate(),
            Err(ToolError::Radius(0.0))
        );
        assert!(sphere(f32::NAN, [1.0; 3]).validate().is_err());
        assert!(sphere(1.0, [f32::INFINITY, 0.0, 0.0]).validate().is_err());
        let paint = Tool::Paint {
            center: [0.0; 3],
            radius: 1.0,
            material: 16,
        };
        assert_eq!(paint.validate(), Err(ToolError::Material(16)));
    }
}
