//! CPU reference renderer: primary ray, Lambert + ambient shading, one shadow ray, sky.
//!
//! `shaders/glsl/render/shade.glsl` mirrors every function here (same constants, same order of
//! operations); see `docs/rendering.md` for the model and the tolerances.

// Per-axis index loops mirror the GLSL vector code one to one.
#![allow(clippy::needless_range_loop)]

use rayon::prelude::*;

use super::params::RenderParams;
use super::{RenderError, RenderOutput, RenderSettings};
use crate::attr::ChunkedColors;
use crate::dag::raycast::{Ray, T_UNBOUNDED};
use crate::dag::{Svdag, VoxelIndex};

// The sRGB curve lives in `crate::color` (shared with import); re-exported for callers here.
pub use crate::color::{linear_to_srgb, srgb_to_linear};

/// Ambient light strength (before the per-axis factor).
pub const AMBIENT: f32 = 0.25;
/// Ambient factor per normal axis (x, y, z), so that flat areas of different orientation read.
pub const AMBIENT_AXIS: [f32; 3] = [0.85, 1.0, 0.7];
/// Strength of the directional light.
pub const DIFFUSE: f32 = 0.75;
/// Linear albedo of voxels when the scene has no colours.
pub const GREY: f32 = 0.6;
/// Linear sky colour at the horizon.
pub const SKY_HORIZON: [f32; 3] = [0.75, 0.82, 0.9];
/// Linear sky colour straight up.
pub const SKY_ZENITH: [f32; 3] = [0.22, 0.42, 0.78];
/// Linear ground colour straight down.
pub const SKY_GROUND: [f32; 3] = [0.32, 0.3, 0.28];

/// Linear sky colour seen along `dir` (not necessarily normalised).
pub fn sky(dir: [f32; 3]) -> [f32; 3] {
    let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    let y = if len > 0.0 { dir[1] / len } else { 0.0 };
    let (far, s) = if y >= 0.0 {
        (SKY_ZENITH, y.min(1.0))
    } else {
        (SKY_GROUND, (-y).min(1.0))
    };
    let mut c = [0.0; 3];
    for k in 0..3 {
        c[k] = SKY_HORIZON[k] + (far[k] - SKY_HORIZON[k]) * s;
    }
    c
}

/// Where the renderers read the colour of a hit voxel.
#[derive(Clone, Copy, Debug)]
pub enum ColorSource<'a> {
    /// One RGBA8 word per voxel (`Svdag::colors`).
    Raw(&'a [u32]),
    /// Encoded colour chunks, decoded per hit (binary search of the chunk + random access).
    Chunked(&'a ChunkedColors),
}

impl ColorSource<'_> {
    /// Number of colours.
    pub fn len(&self) -> u64 {
        match self {
            ColorSource::Raw(c) => c.len() as u64,
            ColorSource::Chunked(c) => c.color_count(),
        }
    }

    /// True when there are no colours.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Colour `index`, or `None` when out of range or undecodable.
    pub fn color(&self, index: u64) -> Option<u32> {
        match self {
            ColorSource::Raw(c) => c.get(index as usize).copied(),
            ColorSource::Chunked(c) => c.color(index).ok(),
        }
    }
}

/// Shades one pixel with the DAG's own colours: `(sRGB-encoded RGBA in [0, 1], primary ray hit)`.
pub fn shade_pixel(
    dag: &Svdag,
    index: &VoxelIndex,
    p: &RenderParams,
    pixel: [u32; 2],
) -> ([f32; 4], bool) {
    shade_pixel_with(dag, index, ColorSource::Raw(&dag.colors), p, pixel)
}

/// Shades one pixel with colours from `colors`.
pub fn shade_pixel_with(
    dag: &Svdag,
    index: &VoxelIndex,
    colors: ColorSource,
    p: &RenderParams,
    pixel: [u32; 2],
) -> ([f32; 4], bool) {
    let ray = p.primary_ray(pixel);
    let Some(hit) = dag.raycast(index, &ray, T_UNBOUNDED) else {
        let c = sky(ray.dir);
        return (
            [
                linear_to_srgb(c[0]),
                linear_to_srgb(c[1]),
                linear_to_srgb(c[2]),
                1.0,
            ],
            false,
        );
    };
    let albedo = if p.has_colors() {
        // Out-of-range indices shade white, like the GPU (which checks `color_count`).
        let rgba = match colors.color(hit.color_index) {
            Some(c) if hit.color_index < p.color_count => c,
            _ => 0xffff_ffff,
        };
        [0, 8, 16].map(|s| srgb_to_linear(((rgba >> s) & 0xff) as f32 / 255.0))
    } else {
        [GREY; 3]
    };
    let n = hit.normal.map(|v| v as f32);
    let axis = if hit.normal[0] != 0 {
        0
    } else if hit.normal[1] != 0 {
        1
    } else {
        2
    };
    let light = [p.light_dir[0], p.light_dir[1], p.light_dir[2]];
    let n_dot_l = (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]).max(0.0);
    let mut direct = DIFFUSE * n_dot_l;
    if p.shadows() && n_dot_l > 0.0 {
        let eps = p.up[3];
        let mut origin = [0.0f32; 3];
        for k in 0..3 {
            origin[k] = (ray.origin[k] + hit.t * ray.dir[k]) + n[k] * eps;
        }
        let shadow = Ray { origin, dir: light };
        if dag.raycast(index, &shadow, T_UNBOUNDED).is_some() {
            direct = 0.0;
        }
    }
    let light_sum = AMBIENT * AMBIENT_AXIS[axis] + direct;
    let c = p.preview_tint(hit.voxel, albedo.map(|a| a * light_sum));
    (
        [
            linear_to_srgb(c[0]),
            linear_to_srgb(c[1]),
            linear_to_srgb(c[2]),
            1.0,
        ],
        true,
    )
}

/// Quantises an sRGB-encoded channel in `[0, 1]` to 8 bits (round to nearest).
pub fn quantize(c: f32) -> u8 {
    (c.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Renders the scene with its own colours on the CPU (rayon over rows), rays built from
/// [`RenderParams`].
pub fn render_cpu(
    dag: &Svdag,
    index: &VoxelIndex,
    settings: &RenderSettings,
) -> Result<RenderOutput, RenderError> {
    render_cpu_with(dag, index, ColorSource::Raw(&dag.colors), settings)
}

/// [`render_cpu`] with colours from `colors` (e.g. decoded from encoded chunks per hit).
pub fn render_cpu_with(
    dag: &Svdag,
    index: &VoxelIndex,
    colors: ColorSource,
    settings: &RenderSettings,
) -> Result<RenderOutput, RenderError> {
    if index.node_voxels.len() != dag.words.len() {
        return Err(RenderError::IndexMismatch {
            index: index.node_voxels.len(),
            words: dag.words.len(),
        });
    }
    let p = RenderParams::with_colors(settings, dag, colors.len())?;
    let (w, h) = (settings.width as usize, settings.height as usize);
    let mut rgba = vec![0u8; w * h * 4];
    let mut hits = vec![0u32; w * h];
    rgba.par_chunks_mut(w * 4)
        .zip(hits.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (row, row_hits))| {
            for x in 0..w {
                let (c, hit) = shade_pixel_with(dag, index, colors, &p, [x as u32, y as u32]);
                for k in 0..4 {
                    row[4 * x + k] = quantize(c[k]);
                }
                row_hits[x] = hit as u32;
            }
        });
    Ok(RenderOutput {
        width: settings.width,
        height: settings.height,
        rgba,
        hits,
    })
}
