//! MagicaVoxel .vox loading with `dot_vox`.
//!
//! * Scene graph (nTRN/nGRP/nSHP): every visible shape is placed with the composed transforms of
//!   its ancestors (first keyframe of each nTRN, first model of each nSHP; nodes or layers with
//!   `_hidden = 1` are skipped). A model voxel `p` of a model of size `s` has its centre at
//!   `p + 1/2 - floor(s/2)` in model space; the rotation and translation map this centre into
//!   the world, and the world voxel is the one with that centre (exact in integers).
//! * No scene graph: model 0 only (multi-model files without a scene graph are animation
//!   frames in the official samples).
//! * MagicaVoxel is z-up and voxdag y-up: `(x, y, z) -> (x, z, -y)` (a proper rotation), then
//!   translated so that the minimum corner is 0, i.e. `(x, z, extent_y - 1 - y)`.
//! * Overlapping voxels: the shape visited last in depth-first scene order wins.
//! * Colours: the palette entry of the voxel (sRGB RGBA8).
//! * Limits (errors, never a panic or a wrap): at most 2^20 scene-graph node visits (a node
//!   shared by several groups is expanded once per path) and 2^40 scaled voxels; the memory
//!   need is estimated with checked arithmetic and compared with `MemAvailable` before the
//!   voxel lists are allocated.

use std::path::Path;

use super::morton;
use super::voxelize::{check_resolution, mem_available};
use super::{guard, ImportOptions, SceneError, Voxels};

/// Integer rigid transform: `p -> r * p + t`, `r` a signed permutation matrix (row-major).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Xform {
    r: [[i64; 3]; 3],
    t: [i64; 3],
}

impl Xform {
    const IDENTITY: Xform = Xform {
        r: [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        t: [0, 0, 0],
    };

    /// Applies the rotation only.
    fn rotate(&self, p: [i64; 3]) -> [i64; 3] {
        let mut o = [0i64; 3];
        for (i, oi) in o.iter_mut().enumerate() {
            *oi = self.r[i][0] * p[0] + self.r[i][1] * p[1] + self.r[i][2] * p[2];
        }
        o
    }

    /// `self ∘ child`.
    fn then(&self, child: &Xform) -> Xform {
        let mut r = [[0i64; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| self.r[i][k] * child.r[k][j]).sum();
            }
        }
        let rt = self.rotate(child.t);
        Xform {
            r,
            t: [rt[0] + self.t[0], rt[1] + self.t[1], rt[2] + self.t[2]],
        }
    }
}

/// Parses a MagicaVoxel `_r` rotation byte (row i: non-zero column and sign).
fn parse_rotation(s: &str) -> Option<[[i64; 3]; 3]> {
    let b: u8 = s.trim().parse().ok()?;
    let c0 = (b & 3) as usize;
    let c1 = ((b >> 2) & 3) as usize;
    if c0 > 2 || c1 > 2 || c0 == c1 {
        return None;
    }
    let c2 = 3 - c0 - c1;
    let mut r = [[0i64; 3]; 3];
    for (row, col) in [c0, c1, c2].into_iter().enumerate() {
        r[row][col] = if b & (1 << (4 + row)) != 0 { -1 } else { 1 };
    }
    Some(r)
}

/// Parses a `_t` translation ("x y z").
fn parse_translation(s: &str) -> Option<[i64; 3]> {
    let v: Vec<i64> = s
        .split_whitespace()
        .map(|x| x.parse::<i32>().map(i64::from))
        .collect::<Result<_, _>>()
        .ok()?;
    (v.len() == 3).then(|| [v[0], v[1], v[2]])
}

/// One placed model: model index and its world transform.
type Placement = (usize, Xform);

/// Most scene-graph nodes [`placements`] visits. A node listed by several groups is expanded
/// once per path, so a small file can describe exponentially many placements (40 groups each
/// listing the next one twice: 2^40); real scenes visit each node once (thousands at most).
const MAX_NODE_VISITS: usize = 1 << 20;

/// Most voxels (after scaling, before removing overlaps) [`load_vox`] accepts.
const MAX_VOXELS: u64 = 1 << 40;

/// Walks the scene graph from node 0 and lists the placed models.
fn placements(path: &Path, data: &dot_vox::DotVoxData) -> Result<Vec<Placement>, SceneError> {
    use dot_vox::SceneNode;
    let perr = |message: String| SceneError::Parse {
        path: path.to_path_buf(),
        format: "vox",
        message,
    };
    let mut out = Vec::new();
    // Explicit stack: (node, parent transform, depth); children pushed in reverse so the
    // visiting order is depth-first in file order.
    let mut stack = vec![(0usize, Xform::IDENTITY, 0usize)];
    let mut visits = 0usize;
    while let Some((id, parent, depth)) = stack.pop() {
        visits += 1;
        if visits > MAX_NODE_VISITS {
            return Err(perr(format!(
                "the scene graph expands to more than {MAX_NODE_VISITS} nodes \
                 (nodes shared by several groups?)"
            )));
        }
        if depth > 4096 {
            return Err(perr("scene graph deeper than 4096 nodes (cycle?)".into()));
        }
        let node = data
            .scenes
            .get(id)
            .ok_or_else(|| perr(format!("scene node {id} does not exist")))?;
        match node {
            SceneNode::Transform {
                attributes,
                frames,
                child,
                layer_id,
            } => {
                let hidden = attributes.get("_hidden").is_some_and(|v| v == "1")
                    || data
                        .layers
                        .get(*layer_id as usize)
                        .is_some_and(|l| l.hidden());
                if hidden {
                    continue;
                }
                let mut local = Xform::IDENTITY;
                if let Some(f) = frames.first() {
                    if let Some(r) = f.attributes.get("_r") {
                        local.r = parse_rotation(r)
                            .ok_or_else(|| perr(format!("node {id}: bad rotation {r:?}")))?;
                    }
                    if let Some(t) = f.attributes.get("_t") {
                        local.t = parse_translation(t)
                            .ok_or_else(|| perr(format!("node {id}: bad translation {t:?}")))?;
                    }
                }
                stack.push((*child as usize, parent.then(&local), depth + 1));
            }
            SceneNode::Group { children, .. } => {
                for c in children.iter().rev() {
                    stack.push((*c as usize, parent, depth + 1));
                }
            }
            SceneNode::Shape { models, .. } => {
                if let Some(m) = models.first() {
                    let mi = m.model_id as usize;
                    if mi >= data.models.len() {
                        return Err(perr(format!("node {id} uses missing model {mi}")));
                    }
                    out.push((mi, parent));
                }
            }
        }
    }
    Ok(out)
}

/// Loads a MagicaVoxel file as voxels (native size times `opts.vox_scale`), y-up.
pub fn load_vox(path: &Path, opts: &ImportOptions) -> Result<Voxels, SceneError> {
    let perr = |message: String| SceneError::Parse {
        path: path.to_path_buf(),
        format: "vox",
        message,
    };
    if opts.vox_scale == 0 {
        return Err(SceneError::BadOption {
            path: path.to_path_buf(),
            reason: "vox_scale must be at least 1".into(),
        });
    }
    if let Some(r) = opts.resolution {
        check_resolution(r, path)?;
    }
    std::fs::metadata(path).map_err(|e| SceneError::Io {
        path: path.to_path_buf(),
        source: e,
    })?;
    // Regular files only, size checked against the memory limit first.
    let bytes = super::read_bounded(path, ".vox file").map_err(perr)?;
    let data = guard(path, "vox", || {
        dot_vox::load_bytes(&bytes).map_err(|e| perr(e.to_string()))
    })?;
    if data.models.is_empty() {
        return Err(perr("no models".into()));
    }
    let placed = if data.scenes.is_empty() {
        vec![(0usize, Xform::IDENTITY)]
    } else {
        placements(path, &data)?
    };

    // Memory guard before any allocation that grows with the voxel count: the world list (one
    // entry per placed model voxel), the scaled Morton list and the output (one entry each per
    // output voxel before deduplication). All products are checked: `vox_scale` is arbitrary.
    let too_large = |reason: String| SceneError::TooLarge {
        path: path.to_path_buf(),
        reason,
    };
    let s = opts.vox_scale as u64;
    let total: u64 = placed.iter().fold(0u64, |acc, (m, _)| {
        acc.saturating_add(data.models[*m].voxels.len() as u64)
    });
    let count = s
        .checked_mul(s)
        .and_then(|s2| s2.checked_mul(s))
        .and_then(|s3| total.checked_mul(s3))
        .ok_or_else(|| {
            too_large(format!(
                "{total} voxels at scale {s}: the scaled voxel count overflows 64 bits"
            ))
        })?;
    const WORLD_BYTES: u64 = std::mem::size_of::<([i64; 3], u32)>() as u64;
    const CODED_BYTES: u64 = std::mem::size_of::<(u64, u32)>() as u64;
    const OUT_BYTES: u64 = 8 + 4;
    let bytes_needed = total
        .saturating_mul(WORLD_BYTES)
        .saturating_add(count.saturating_mul(CODED_BYTES + OUT_BYTES));
    if count > MAX_VOXELS || mem_available().is_some_and(|a| bytes_needed > a) {
        return Err(too_large(format!(
            "{count} voxels at scale {s} need about {} MiB",
            bytes_needed >> 20
        )));
    }

    // World voxel positions (MagicaVoxel z-up) with palette colours.
    let mut world: Vec<([i64; 3], u32)> = Vec::with_capacity(total as usize);
    for (mi, xf) in &placed {
        let model = &data.models[*mi];
        let half = [
            (model.size.x / 2) as i64,
            (model.size.y / 2) as i64,
            (model.size.z / 2) as i64,
        ];
        for v in &model.voxels {
            // Doubled centre relative to the pivot: 2p + 1 - 2 floor(s/2) (odd).
            let c2 = [
                2 * (v.x as i64 - half[0]) + 1,
                2 * (v.y as i64 - half[1]) + 1,
                2 * (v.z as i64 - half[2]) + 1,
            ];
            let r = xf.rotate(c2);
            let p = [
                (r[0] + 2 * xf.t[0] - 1).div_euclid(2),
                (r[1] + 2 * xf.t[1] - 1).div_euclid(2),
                (r[2] + 2 * xf.t[2] - 1).div_euclid(2),
            ];
            let col = data
                .palette
                .get(v.i as usize)
                .map(|c| c.r as u32 | (c.g as u32) << 8 | (c.b as u32) << 16 | (c.a as u32) << 24)
                .unwrap_or(0xffff_ffff);
            // z-up -> y-up: (x, y, z) -> (x, z, -y).
            world.push(([p[0], p[2], -p[1]], col));
        }
    }
    if world.is_empty() {
        return Err(perr("the scene has no visible voxels".into()));
    }
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for (p, _) in &world {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let native_extent = (0..3)
        .map(|a| (hi[a] - lo[a] + 1) as u64)
        .max()
        .unwrap_or(1);
    let extent = native_extent.checked_mul(s).ok_or_else(|| {
        too_large(format!(
            "extent {native_extent} at scale {s} overflows 64 bits"
        ))
    })?;
    let resolution = match opts.resolution {
        Some(r) => {
            if extent > r as u64 {
                return Err(SceneError::TooLarge {
                    path: path.to_path_buf(),
                    reason: format!("scaled extent {extent} does not fit resolution {r}"),
                });
            }
            r
        }
        None => {
            let max = super::voxelize::MAX_VOXELIZE_RESOLUTION;
            if extent > max as u64 {
                return Err(SceneError::TooLarge {
                    path: path.to_path_buf(),
                    reason: format!("scaled extent {extent} exceeds the maximum resolution {max}"),
                });
            }
            extent.max(8).next_power_of_two() as u32
        }
    };
    // Morton codes; the stable sort keeps scene order among duplicates, the last one wins.
    let mut coded: Vec<(u64, u32)> = Vec::with_capacity(count as usize);
    for (p, col) in &world {
        let base = [
            (p[0] - lo[0]) as u32 * s as u32,
            (p[1] - lo[1]) as u32 * s as u32,
            (p[2] - lo[2]) as u32 * s as u32,
        ];
        for dz in 0..s as u32 {
            for dy in 0..s as u32 {
                for dx in 0..s as u32 {
                    coded.push((
                        morton::encode(base[0] + dx, base[1] + dy, base[2] + dz),
                        *col,
                    ));
                }
            }
        }
    }
    drop(world);
    coded.sort_by_key(|c| c.0);
    let mut out = Voxels {
        resolution,
        codes: Vec::with_capacity(coded.len()),
        colors: Vec::with_capacity(coded.len()),
    };
    for (code, col) in coded {
        if out.codes.last() == Some(&code) {
            *out.colors.last_mut().expect("same length as codes") = col;
        } else {
            out.codes.push(code);
            out.colors.push(col);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_byte_decoding() {
        // Identity: row 0 -> col 0, row 1 -> col 1.
        assert_eq!(parse_rotation("4"), Some([[1, 0, 0], [0, 1, 0], [0, 0, 1]]));
        // The example of the format description: R = [[0,1,0],[0,0,-1],[-1,0,0]].
        let b = 1 | (2 << 2) | (1 << 5) | (1 << 6);
        assert_eq!(
            parse_rotation(&b.to_string()),
            Some([[0, 1, 0], [0, 0, -1], [-1, 0, 0]])
        );
        assert_eq!(parse_rotation("0"), None); // both rows in column 0
        assert_eq!(parse_rotation("x"), None);
    }

    #[test]
    fn transform_composition() {
        let a = Xform {
            r: [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
            t: [10, 0, 0],
        };
        let b = Xform {
            r: Xform::IDENTITY.r,
            t: [1, 2, 3],
        };
        let ab = a.then(&b);
        // a(b(p)) for p = 0: a([1,2,3]) = [-2, 1, 3] + [10, 0, 0]
        assert_eq!(ab.t, [8, 1, 3]);
        assert_eq!(ab.r, a.r);
    }
}
