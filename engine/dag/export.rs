//! Export of a DAG's voxels: raw little-endian u32 coordinates, and MagicaVoxel `.vox`.

use std::io::{self, Write};
use std::path::Path;

use rustc_hash::FxHashMap;

use super::file::write_atomic;
use super::{DagError, Svdag};
use crate::scene::morton;

/// Writes x, y, z (little-endian u32 each, 12 bytes per voxel) of every occupied voxel in
/// Morton order.
pub fn export_xyz_u32(dag: &Svdag, w: &mut impl Write) -> io::Result<()> {
    let mut buf: Vec<u8> = Vec::with_capacity(12 * 4096);
    let mut result = Ok(());
    dag.for_each_voxel(|code| {
        if result.is_err() {
            return;
        }
        for c in morton::decode(code) {
            buf.extend_from_slice(&c.to_le_bytes());
        }
        if buf.len() >= 12 * 4096 {
            result = w.write_all(&buf);
            buf.clear();
        }
    });
    result?;
    w.write_all(&buf)
}

/// [`export_xyz_u32`] into a file, written atomically.
pub fn export_xyz_u32_file(dag: &Svdag, path: &Path) -> Result<(), DagError> {
    write_atomic(path, |w| export_xyz_u32(dag, w))
}

/// Uniform RGB cube used when a scene has more than 255 distinct colours: 6 x 7 x 6 = 252
/// entries (green gets the extra step), alpha forced to 255.
const CUBE: [u32; 3] = [6, 7, 6];

/// Palette index of `rgba` in the uniform cube: each channel rounded to its nearest step.
fn cube_index(rgba: u32) -> u8 {
    let q = |v: u32, steps: u32| (v * (steps - 1) + 127) / 255;
    let (r, g, b) = (rgba & 0xff, rgba >> 8 & 0xff, rgba >> 16 & 0xff);
    (q(r, CUBE[0]) + CUBE[0] * (q(g, CUBE[1]) + CUBE[1] * q(b, CUBE[2]))) as u8
}

/// Colour of cube entry `i`.
fn cube_color(i: u32) -> dot_vox::Color {
    let level = |v: u32, steps: u32| ((v * 255 + (steps - 1) / 2) / (steps - 1)) as u8;
    dot_vox::Color {
        r: level(i % CUBE[0], CUBE[0]),
        g: level(i / CUBE[0] % CUBE[1], CUBE[1]),
        b: level(i / (CUBE[0] * CUBE[1]), CUBE[2]),
        a: 255,
    }
}

/// RGBA8 word to a `dot_vox` colour.
fn to_color(rgba: u32) -> dot_vox::Color {
    let [r, g, b, a] = rgba.to_le_bytes();
    dot_vox::Color { r, g, b, a }
}

/// Palette (at most 255 entries) and one palette index per voxel, in colour order.
///
/// No colours: one grey entry. At most 255 distinct colours: exact, in first-use order.
/// More: the 252-entry uniform RGB cube of [`CUBE`] (nearest step per channel).
fn quantise(colors: &[u32], voxels: u64) -> (Vec<dot_vox::Color>, Vec<u8>) {
    if colors.is_empty() {
        let grey = dot_vox::Color {
            r: 128,
            g: 128,
            b: 128,
            a: 255,
        };
        return (vec![grey], vec![0; voxels as usize]);
    }
    let mut exact: FxHashMap<u32, u8> = FxHashMap::default();
    let mut palette = Vec::new();
    for &c in colors {
        if let std::collections::hash_map::Entry::Vacant(slot) = exact.entry(c) {
            if palette.len() == 255 {
                let palette = (0..CUBE.iter().product()).map(cube_color).collect();
                return (palette, colors.iter().map(|&c| cube_index(c)).collect());
            }
            slot.insert(palette.len() as u8);
            palette.push(to_color(c));
        }
    }
    (palette, colors.iter().map(|c| exact[c]).collect())
}

/// Writes a MagicaVoxel `.vox` file (one N^3 model, N <= 256), atomically.
///
/// Converts voxdag's y-up grid back to MagicaVoxel's z-up one: voxdag (x, y, z) becomes
/// .vox (x, N - 1 - z, y), the inverse of the import mapping (x, y, z)_vox -> (x, z, N - 1 - y).
pub fn export_vox(dag: &Svdag, path: &Path) -> Result<(), DagError> {
    let n = dag.resolution;
    if n > 256 {
        return Err(DagError::Export {
            path: path.to_path_buf(),
            reason: format!("MagicaVoxel .vox holds at most 256^3 voxels; this DAG is {n}^3"),
        });
    }
    let voxel_count = dag.voxel_count();
    let (mut palette, indices) = quantise(&dag.colors, voxel_count);
    let mut voxels = Vec::with_capacity(voxel_count as usize);
    dag.for_each_voxel(|code| {
        let [x, y, z] = morton::decode(code);
        voxels.push(dot_vox::Voxel {
            x: x as u8,
            y: (n - 1 - z) as u8,
            z: y as u8,
            i: indices[voxels.len()],
        });
    });
    // The RGBA chunk always has 256 entries; entry i is file colour index i + 1.
    palette.resize(
        256,
        dot_vox::Color {
            r: 0,
            g: 0,
            b: 0,
            a: 255,
        },
    );
    let data = dot_vox::DotVoxData {
        version: 150,
        index_map: Vec::new(),
        models: vec![dot_vox::Model {
            size: dot_vox::Size { x: n, y: n, z: n },
            voxels,
        }],
        palette,
        materials: Vec::new(),
        scenes: Vec::new(),
        layers: Vec::new(),
    };
    write_atomic(path, |w| data.write_vox(w))
}
