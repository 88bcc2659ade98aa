//! The `forest` test scene: the landscape's terrain with groves of procedural trees and, between
//! them, copies of the scanned meshes.
//!
//! Why a second scene: proxies pay where a batching point's box is mostly empty space that rays
//! cross without hitting anything. The landscape's copies of scanned meshes are solid surfaces
//! that fill their points' boxes, so there proxies save little beyond reloads
//! (docs/out-of-core.md); the dissertation's scenes are vegetation (leaves in clusters, thin
//! branches, gaps everywhere), which this scene stands in for. Trees are a few variants built
//! once and instanced thousands of times, as vegetation is in production scenes.

use super::geom::Aabb;
use super::prepare::{mix64, unit, Instance, SceneSource, SourceMesh, Terrain};
use super::OocError;

/// Tree variants per scene (each a mesh instanced many times).
const TREE_VARIANTS: u64 = 8;
/// Triangles of a tree variant, about (leaves make up the rest after trunk and branches).
const TREE_TRIANGLES: u32 = 12_000;
/// Trees per grove.
const GROVE_TREES: u64 = 24;
/// Share of the non-terrain triangles that are trees; the rest are scanned-mesh copies.
const TREE_SHARE: f64 = 0.75;

/// A deterministic stream of uniform numbers from a seed (splitmix64 over a counter).
struct Stream {
    seed: u64,
    n: u64,
}

impl Stream {
    fn new(seed: u64) -> Stream {
        Stream { seed, n: 0 }
    }

    /// The next number, uniform in [0, 1).
    fn next(&mut self) -> f64 {
        self.n += 1;
        unit(mix64(self.seed ^ mix64(self.n)))
    }

    /// A point uniform in the unit ball (rejection sampling).
    fn in_ball(&mut self) -> [f64; 3] {
        loop {
            let p = [0; 3].map(|_| self.next() * 2.0 - 1.0);
            if p[0] * p[0] + p[1] * p[1] + p[2] * p[2] <= 1.0 {
                return p;
            }
        }
    }
}

/// Appends a prism of `sides` faces (no caps) from `a` (radius `ra`) to `b` (radius `rb`);
/// nothing when `a` and `b` coincide.
fn prism(mesh: &mut SourceMesh, a: [f64; 3], b: [f64; 3], ra: f64, rb: f64, sides: u32) {
    let d = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if len < 1e-9 {
        return; // no axis: nothing to draw
    }
    let d = d.map(|v| v / len);
    let helper = if d[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let cross = |x: [f64; 3], y: [f64; 3]| {
        [
            x[1] * y[2] - x[2] * y[1],
            x[2] * y[0] - x[0] * y[2],
            x[0] * y[1] - x[1] * y[0],
        ]
    };
    let u = cross(d, helper);
    let ul = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    let u = u.map(|v| v / ul);
    let w = cross(d, u);
    let base = mesh.positions.len() as u32;
    for k in 0..sides {
        let angle = std::f64::consts::TAU * k as f64 / sides as f64;
        let (s, c) = angle.sin_cos();
        for (centre, r) in [(a, ra), (b, rb)] {
            let p = [0, 1, 2].map(|i| (centre[i] + r * (c * u[i] + s * w[i])) as f32);
            mesh.positions.push(p);
        }
    }
    for k in 0..sides {
        let (a0, b0) = (base + 2 * k, base + 2 * k + 1);
        let next = (k + 1) % sides;
        let (a1, b1) = (base + 2 * next, base + 2 * next + 1);
        mesh.triangles.push([a0, b0, a1]);
        mesh.triangles.push([a1, b0, b1]);
    }
}

/// A tree of height 1 standing on the origin: a tapered trunk, branches from the trunk's top
/// to leaf clusters spread over an ellipsoidal crown, and `triangles` in all (about), most of
/// them leaves (one small triangle each, randomly oriented around its cluster's centre).
pub fn tree_mesh(seed: u64, triangles: u32) -> SourceMesh {
    let mut rng = Stream::new(seed);
    let mut mesh = SourceMesh::default();
    let trunk_top = 0.4 + 0.1 * rng.next();
    prism(
        &mut mesh,
        [0.0, 0.0, 0.0],
        [0.0, trunk_top, 0.0],
        0.035,
        0.025,
        8,
    );
    let clusters = 24 + (rng.next() * 16.0) as u32;
    let crown = [0.22 + 0.1 * rng.next(), 0.25, 0.22 + 0.1 * rng.next()];
    let centres: Vec<[f64; 3]> = (0..clusters)
        .map(|_| {
            let p = rng.in_ball();
            [p[0] * crown[0], 0.7 + p[1] * crown[1], p[2] * crown[2]]
        })
        .collect();
    for c in &centres {
        let from = [0.0, trunk_top * (0.8 + 0.2 * rng.next()), 0.0];
        prism(&mut mesh, from, *c, 0.008, 0.004, 4);
    }
    let leaves = triangles.saturating_sub(mesh.triangles.len() as u32).max(1);
    for i in 0..leaves {
        let c = centres[(i % clusters) as usize];
        let p = rng.in_ball();
        let centre = [0, 1, 2].map(|k| c[k] + 0.07 * p[k]);
        let base = mesh.positions.len() as u32;
        for _ in 0..3 {
            let q = rng.in_ball();
            mesh.positions
                .push([0, 1, 2].map(|k| (centre[k] + 0.02 * q[k]) as f32));
        }
        mesh.triangles.push([base, base + 1, base + 2]);
    }
    mesh
}

impl SceneSource {
    /// A forest: the landscape's terrain (about a tenth of `triangles`), then groves of
    /// procedural trees (8 variants, about 12 000 triangles each, in groves of 24 within 40
    /// units of the grove's centre) and copies of `meshes` scattered as in
    /// [`SceneSource::landscape`], three quarters of the rest trees; all from `seed`.
    pub fn forest(
        meshes: Vec<SourceMesh>,
        triangles: u64,
        seed: u64,
    ) -> Result<SceneSource, OocError> {
        let mut scene = SceneSource::terrain_for(meshes, triangles, seed)?;
        let terrain: Terrain = scene.terrain.expect("terrain_for makes a terrain");
        let scanned = scene.meshes.len();
        scene.meshes.extend(
            (0..TREE_VARIANTS).map(|v| tree_mesh(mix64(seed ^ mix64(0x7ee5 + v)), TREE_TRIANGLES)),
        );
        let bounds: Vec<Aabb> = scene.meshes.iter().map(SourceMesh::bounds).collect();
        let mut total = scene.triangle_count();
        let tree_budget = total + (triangles.saturating_sub(total) as f64 * TREE_SHARE) as u64;
        let size = terrain.size;
        let mut rng = Stream::new(mix64(seed ^ 0xf0e5));
        let mut trees = 0u64;
        let mut grove = [0.0; 2];
        while total < tree_budget {
            if trees.is_multiple_of(GROVE_TREES) {
                grove = [rng.next() * size, rng.next() * size];
            }
            let variant = scanned + (rng.next() * TREE_VARIANTS as f64) as usize;
            let r = 40.0 * rng.next().sqrt();
            let a = rng.next() * std::f64::consts::TAU;
            let x = (grove[0] + r * a.cos()).clamp(0.0, size);
            let z = (grove[1] + r * a.sin()).clamp(0.0, size);
            let height = size * (0.012 + 0.012 * rng.next());
            let angle = rng.next() * std::f64::consts::TAU;
            scene.instances.push(Instance::standing(
                variant as u32,
                &bounds[variant],
                height,
                angle,
                [x, terrain.height_at(x, z), z],
                0.002 * size,
            ));
            total += scene.meshes[variant].triangles.len() as u64;
            trees += 1;
        }
        scene.scatter_copies(&bounds[..scanned], seed, triangles);
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tree_meshes_are_deterministic_sized_and_standing() {
        let a = tree_mesh(5, 3000);
        let b = tree_mesh(5, 3000);
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.triangles, b.triangles);
        assert_ne!(tree_mesh(6, 3000).positions, a.positions);
        assert_eq!(a.triangles.len(), 3000);
        let n = a.positions.len() as u32;
        assert!(a.triangles.iter().flatten().all(|&i| i < n));
        let b = a.bounds();
        assert!(b.lo[1] >= 0.0 && b.lo[1] < 0.01, "{b:?}");
        assert!(b.hi[1] > 0.8 && b.hi[1] <= 1.1, "{b:?}");
        assert!(b.hi[0] - b.lo[0] < 1.0 && b.hi[2] - b.lo[2] < 1.0, "{b:?}");
    }

    #[test]
    fn forest_has_terrain_trees_and_copies_and_the_triangles_asked() {
        let rock = tree_mesh(99, 500);
        let scene = SceneSource::forest(vec![rock], 1_000_000, 3).unwrap();
        let total = scene.triangle_count();
        assert!((1_000_000..1_000_000 + TREE_TRIANGLES as u64).contains(&total));
        let trees = scene.instances.iter().filter(|i| i.mesh > 0).count();
        let copies = scene.instances.len() - trees;
        // Three quarters of the 900 000 non-terrain triangles are trees of 12 000 each.
        assert!((55..=58).contains(&trees), "{trees} trees");
        assert!(copies > 400, "{copies} copies");
        let again = SceneSource::forest(vec![tree_mesh(99, 500)], 1_000_000, 3).unwrap();
        assert_eq!(again.instances, scene.instances);
    }
}
