//! Path tracing: settings, the counter-based RNG and sampling shared with the GPU, the CPU
//! reference path tracer and the output image (tonemapped PNG, linear OpenEXR).
//!
//! Model (docs/pathtracing.md): Lambertian voxels lit by a constant environment and an optional
//! sun (a directional light sampled by next-event estimation); `bounces` = B diffuse surface
//! interactions a path may have before it must escape (Mitsuba's `max_depth` = B + 1); Russian
//! roulette from interaction `rr_depth` on. Every function here has a GLSL twin in
//! `shaders/glsl/render/pt_common.glsl` performing the same f32 operations in the same order,
//! and the hits come from the exact-matching traversal ([`Svdag::raycast`]), so the GPU path
//! tracers (`pathtrace_gpu`) and this reference trace the same paths wherever the driver's
//! division and square root are correctly rounded (lavapipe).

// Per-axis index loops mirror the GLSL vector code one to one.
#![allow(clippy::needless_range_loop)]

use std::io;
use std::path::{Path, PathBuf};

use rayon::prelude::*;

use super::cpu::{linear_to_srgb, quantize, ColorSource, GREY};
pub use super::gpu_shared::PtParams;
use super::params::RenderParams;
use super::FirstHit;
use super::{RenderError, RenderSettings};
use crate::dag::raycast::{Hit, Ray, T_UNBOUNDED};
use crate::dag::{Svdag, VoxelIndex};

/// Default number of surface interactions (`--bounces`): the dissertation's setup.
pub const DEFAULT_BOUNCES: u32 = 4;
/// Default first interaction that plays Russian roulette.
pub const DEFAULT_RR_DEPTH: u32 = 3;
/// Largest `--bounces` accepted.
pub const MAX_BOUNCES: u32 = 1024;
/// Largest probability of surviving Russian roulette.
pub const RR_MAX: f32 = 0.95;
/// `1 / pi` as an f32 (`PT_INV_PI`).
const INV_PI: f32 = f32::from_bits(0x3ea2_f983);
/// `pi / 2` as an f32 (`PT_HALF_PI`).
const HALF_PI: f32 = f32::from_bits(0x3fc9_0fdb);
/// `2^-24`.
const INV_2_24: f32 = f32::from_bits(0x3380_0000);

/// A directional light sampled by next-event estimation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sun {
    /// Direction towards the sun (normalised when used).
    pub dir: [f32; 3],
    /// Irradiance on a surface facing it.
    pub intensity: f32,
}

/// What a path-traced render needs besides the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PtSettings {
    /// Image size and camera (the raster light and shadow settings are not used).
    pub render: RenderSettings,
    /// Samples per pixel (>= 1).
    pub spp: u32,
    /// Surface interactions a path may have before it must escape.
    pub bounces: u32,
    /// Constant environment radiance (linear RGB, >= 0).
    pub env: [f32; 3],
    /// Optional sun.
    pub sun: Option<Sun>,
    /// Uniform albedo in [0, 1] instead of the voxel colours.
    pub albedo: Option<f32>,
    /// RNG seed.
    pub seed: u32,
    /// First interaction that plays Russian roulette (`bounces + 1` or more: never).
    pub rr_depth: u32,
}

impl PtSettings {
    /// Defaults: 1 spp, [`DEFAULT_BOUNCES`], white environment 1, no sun, voxel colours, seed 0.
    pub fn new(render: RenderSettings) -> PtSettings {
        PtSettings {
            render,
            spp: 1,
            bounces: DEFAULT_BOUNCES,
            env: [1.0; 3],
            sun: None,
            albedo: None,
            seed: 0,
            rr_depth: DEFAULT_RR_DEPTH,
        }
    }

    /// Checks the values a user can pass.
    pub fn validate(&self) -> Result<(), PathTraceError> {
        let bad = |m: String| Err(PathTraceError::Invalid(m));
        if self.spp == 0 {
            return bad("--spp must be at least 1".into());
        }
        if self.bounces > MAX_BOUNCES {
            return bad(format!("--bounces {} exceeds {MAX_BOUNCES}", self.bounces));
        }
        if self.env.iter().any(|v| !v.is_finite() || *v < 0.0) {
            return bad(format!(
                "--env {:?}: radiance must be finite and >= 0",
                self.env
            ));
        }
        if let Some(a) = self.albedo {
            if !(0.0..=1.0).contains(&a) {
                return bad(format!("--albedo {a}: must lie in [0, 1]"));
            }
        }
        if let Some(sun) = self.sun {
            if !sun.intensity.is_finite() || sun.intensity < 0.0 {
                return bad(format!(
                    "--sun intensity {}: must be finite and >= 0",
                    sun.intensity
                ));
            }
            if super::camera::normalize(sun.dir).is_none() {
                return bad(format!(
                    "--sun direction {:?} is zero or not finite",
                    sun.dir
                ));
            }
        }
        Ok(())
    }

    /// The GPU/CPU constants: [`PtParams`] without buffer addresses.
    pub fn params(&self) -> Result<PtParams, PathTraceError> {
        self.validate()?;
        let (sun_dir, intensity) = match self.sun {
            Some(s) if s.intensity > 0.0 => (
                super::camera::normalize(s.dir).expect("validated"),
                s.intensity,
            ),
            _ => ([0.0; 3], 0.0),
        };
        let pixels = self.render.width as u64 * self.render.height as u64;
        if pixels > u32::MAX as u64 {
            return Err(PathTraceError::Invalid(format!(
                "{}x{} pixels: at most 2^32 - 1",
                self.render.width, self.render.height
            )));
        }
        Ok(PtParams {
            env: [
                self.env[0],
                self.env[1],
                self.env[2],
                self.albedo.unwrap_or(-1.0),
            ],
            sun: [sun_dir[0], sun_dir[1], sun_dir[2], intensity],
            accum: 0,
            first_hits: 0,
            srgb_lut: 0,
            paths: 0,
            queue_a: 0,
            queue_b: 0,
            flags: 0,
            ext_count: 0,
            shadow_queue: 0,
            shadow_count: 0,
            bounces: self.bounces,
            seed: self.seed,
            rr_depth: self.rr_depth,
            pixels: pixels as u32,
        })
    }
}

/// Errors of the path tracers.
#[derive(Debug, thiserror::Error)]
pub enum PathTraceError {
    /// A setting is out of range.
    #[error("{0}")]
    Invalid(String),
    /// Camera, image size or scene rejected by the renderer.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// A GPU operation failed.
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    /// The output file's extension is neither .png nor .exr.
    #[error("{0}: output must end in .png or .exr")]
    Extension(PathBuf),
    /// Writing the image failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// File being written.
        path: PathBuf,
        /// Underlying error.
        source: io::Error,
    },
}

/// PCG hash (Jarzynski & Olano 2020): a bijection of `u32` (`pt_pcg`).
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// Key of the path of `pixel` (row-major index) in sample `sample`:
/// `pcg(pcg(pcg(seed) ^ pixel) ^ sample)`.
pub fn path_key(seed: u32, pixel: u32, sample: u32) -> u32 {
    pcg_hash(pcg_hash(pcg_hash(seed) ^ pixel) ^ sample)
}

/// Uniform number in `[0, 1)` (a multiple of 2^-24) for dimension `dim` of bounce `bounce`:
/// `(pcg(key ^ pcg(4 bounce + dim)) >> 8) * 2^-24`.
pub fn random(key: u32, bounce: u32, dim: u32) -> f32 {
    let h = pcg_hash(key ^ pcg_hash(bounce.wrapping_mul(4).wrapping_add(dim)));
    (h >> 8) as f32 * INV_2_24
}

/// `(sin a, cos a)` for `a` in `[0, pi/2)`: Taylor polynomials of degree 11 and 12 (`pt_sincos`).
pub fn sincos(a: f32) -> (f32, f32) {
    let a2 = a * a;
    let mut ps = f32::from_bits(0xb2d7_322b);
    for bits in [0x3638_ef1d, 0xb950_0d01, 0x3c08_8889, 0xbe2a_aaab] {
        ps = ps * a2 + f32::from_bits(bits);
    }
    ps = ps * a2 + 1.0;
    let s = ps * a;
    let mut pc = f32::from_bits(0x310f_76c7);
    for bits in [0xb493_f27e, 0x37d0_0d01, 0xbab6_0b61, 0x3d2a_aaab] {
        pc = pc * a2 + f32::from_bits(bits);
    }
    pc = pc * a2 + -0.5;
    (s, pc * a2 + 1.0)
}

/// Axis of an axis-aligned normal.
fn normal_axis(n: [i32; 3]) -> usize {
    if n[0] != 0 {
        0
    } else if n[1] != 0 {
        1
    } else {
        2
    }
}

/// Cosine-weighted direction around the axis normal `n` from two uniform numbers
/// (`pt_cosine_direction`).
pub fn cosine_direction(n: [i32; 3], u1: f32, u2: f32) -> [f32; 3] {
    let r = u1.sqrt();
    let x4 = 4.0 * u2;
    let q = x4 as u32;
    let f = x4 - q as f32;
    let (s, c) = sincos(f * HALF_PI);
    let (dx, dy) = match q {
        1 => (-s, c),
        2 => (-c, -s),
        3 => (s, -c),
        _ => (c, s),
    };
    let (lx, ly, lz) = (r * dx, r * dy, (1.0 - u1).sqrt());
    let axis = normal_axis(n);
    let mut d = [0.0; 3];
    d[axis] = if n[axis] > 0 { lz } else { -lz };
    d[(axis + 1) % 3] = lx;
    d[(axis + 2) % 3] = ly;
    d
}

/// Camera ray through `pixel + (jx, jy)` (`pt_camera_ray`).
pub fn camera_ray(p: &RenderParams, pixel: [u32; 2], jx: f32, jy: f32) -> Ray {
    let px = pixel[0] as f32 + jx;
    let py = pixel[1] as f32 + jy;
    let u = (px - 0.5 * p.width as f32) * p.right[3];
    let v = (0.5 * p.height as f32 - py) * p.right[3];
    let mut dir = [0.0f32; 3];
    for k in 0..3 {
        dir[k] = (p.forward[k] + u * p.right[k]) + v * p.up[k];
    }
    Ray {
        origin: [p.eye[0], p.eye[1], p.eye[2]],
        dir,
    }
}

/// sRGB byte -> linear table shared by both tracers (the GPU reads it from a buffer, so no
/// `pow` of the driver's precision enters the albedo).
pub fn srgb_lut() -> [f32; 256] {
    std::array::from_fn(|i| crate::color::srgb_to_linear(i as f32 / 255.0))
}

/// The first hit of a camera ray as [`FirstHit`] (`None`: a miss, all zero), as
/// `primary.comp` and the GPU path tracers write it.
pub fn first_hit(hit: Option<&Hit>) -> FirstHit {
    match hit {
        Some(h) => FirstHit {
            hit: 1,
            t_bits: h.t.to_bits(),
            voxel: h.voxel,
            normal: h.normal,
            color_index: h.color_index,
        },
        None => FirstHit::default(),
    }
}

/// A scene prepared for the CPU path tracer.
pub struct CpuScene<'a> {
    /// The DAG.
    pub dag: &'a Svdag,
    /// Its voxel index (colour indexing).
    pub index: &'a VoxelIndex,
    /// Where hit colours come from.
    pub colors: ColorSource<'a>,
}

/// The radiance of one path (`pt_mega.comp`'s loop) and the rays it traced; its first hit when
/// `first` is set.
fn trace_path(
    scene: &CpuScene,
    p: &RenderParams,
    pt: &PtParams,
    lut: &[f32; 256],
    pixel: [u32; 2],
    sample: u32,
    first: Option<&mut FirstHit>,
) -> ([f32; 3], u64) {
    let index = pixel[1] * p.width + pixel[0];
    let key = path_key(pt.seed, index, sample);
    let mut ray = camera_ray(p, pixel, random(key, 0, 0), random(key, 0, 1));
    let mut throughput = [1.0f32; 3];
    let mut radiance = [0.0f32; 3];
    let sun = [pt.sun[0], pt.sun[1], pt.sun[2]];
    let mut first = first;
    let mut rays = 0;
    for k in 0..=pt.bounces {
        let hit = scene.dag.raycast(scene.index, &ray, T_UNBOUNDED);
        rays += 1;
        if k == 0 {
            if let Some(f) = first.take() {
                *f = first_hit(hit.as_ref());
            }
        }
        let Some(hit) = hit else {
            for c in 0..3 {
                radiance[c] += throughput[c] * pt.env[c];
            }
            break;
        };
        let i = k + 1;
        if i > pt.bounces {
            break;
        }
        let albedo = albedo(scene, p, pt, lut, hit.color_index);
        let n = hit.normal.map(|v| v as f32);
        let mut start = [0.0f32; 3];
        for c in 0..3 {
            start[c] = (ray.origin[c] + hit.t * ray.dir[c]) + n[c] * p.up[3];
        }
        if pt.sun[3] > 0.0 {
            let n_dot_l = n[0] * sun[0] + n[1] * sun[1] + n[2] * sun[2];
            if n_dot_l > 0.0 {
                let shadow = Ray {
                    origin: start,
                    dir: sun,
                };
                rays += 1;
                if scene
                    .dag
                    .raycast(scene.index, &shadow, T_UNBOUNDED)
                    .is_none()
                {
                    let e = (pt.sun[3] * n_dot_l) * INV_PI;
                    for c in 0..3 {
                        radiance[c] += (throughput[c] * albedo[c]) * e;
                    }
                }
            }
        }
        let dir = cosine_direction(hit.normal, random(key, i, 0), random(key, i, 1));
        ray = Ray { origin: start, dir };
        for c in 0..3 {
            throughput[c] *= albedo[c];
        }
        if i >= pt.rr_depth && !roulette(&mut throughput, random(key, i, 2)) {
            break;
        }
    }
    (radiance, rays)
}

/// Russian roulette (`pt_roulette`): survive with `p = min(max channel, 0.95)`, then divide.
fn roulette(throughput: &mut [f32; 3], u: f32) -> bool {
    let p = throughput[0]
        .max(throughput[1])
        .max(throughput[2])
        .min(RR_MAX);
    if u >= p {
        return false;
    }
    for c in throughput.iter_mut() {
        *c /= p;
    }
    true
}

/// Linear albedo of a hit (`pt_albedo`).
fn albedo(
    scene: &CpuScene,
    p: &RenderParams,
    pt: &PtParams,
    lut: &[f32; 256],
    color_index: u64,
) -> [f32; 3] {
    if pt.env[3] >= 0.0 {
        return [pt.env[3]; 3];
    }
    if !p.has_colors() {
        return [GREY; 3];
    }
    let rgba = match scene.colors.color(color_index) {
        Some(c) if color_index < p.color_count => c,
        _ => 0xffff_ffff,
    };
    [0, 8, 16].map(|s| lut[((rgba >> s) & 0xff) as usize])
}

/// A path-traced image: linear radiance per pixel and the first hits of sample 0.
#[derive(Clone, Debug, PartialEq)]
pub struct PtImage {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Samples accumulated.
    pub spp: u32,
    /// Summed radiance per pixel (rgb) and sample count (w), row-major.
    pub accum: Vec<[f32; 4]>,
    /// First hit of each pixel's camera ray in sample 0.
    pub first_hits: Vec<FirstHit>,
    /// Rays traced (camera, bounce and shadow rays): counted by the CPU reference only.
    pub rays: Option<u64>,
}

impl PtImage {
    /// Mean linear radiance per pixel, RGB row-major.
    pub fn linear(&self) -> Vec<f32> {
        let inv = 1.0 / self.spp.max(1) as f32;
        self.accum
            .iter()
            .flat_map(|a| [a[0] * inv, a[1] * inv, a[2] * inv])
            .collect()
    }

    /// Tonemapped RGBA8: clamp to [0, 1], sRGB curve, round (alpha 255).
    pub fn to_rgba8(&self) -> Vec<u8> {
        self.linear()
            .chunks_exact(3)
            .flat_map(|c| {
                [
                    quantize(linear_to_srgb(c[0])),
                    quantize(linear_to_srgb(c[1])),
                    quantize(linear_to_srgb(c[2])),
                    255,
                ]
            })
            .collect()
    }

    /// Writes `.png` (tonemapped sRGB) or `.exr` (linear RGB f32), atomically.
    pub fn save(&self, path: &Path) -> Result<(), PathTraceError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        let (w, h) = (self.width, self.height);
        let written = match ext.as_deref() {
            Some("png") => {
                let rgba = self.to_rgba8();
                crate::atomic_file::write_atomic(path, |writer| {
                    image::ImageEncoder::write_image(
                        image::codecs::png::PngEncoder::new(writer),
                        &rgba,
                        w,
                        h,
                        image::ExtendedColorType::Rgba8,
                    )
                    .map_err(io::Error::other)
                })
            }
            Some("exr") => {
                let linear = self.linear();
                crate::atomic_file::write_atomic(path, |writer| {
                    image::ImageEncoder::write_image(
                        image::codecs::openexr::OpenExrEncoder::new(writer),
                        bytemuck::cast_slice(&linear),
                        w,
                        h,
                        image::ExtendedColorType::Rgb32F,
                    )
                    .map_err(io::Error::other)
                })
            }
            _ => return Err(PathTraceError::Extension(path.to_path_buf())),
        };
        written.map_err(|source| PathTraceError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Checks an output path's extension before any work.
pub fn check_extension(path: &Path) -> Result<(), PathTraceError> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("png") || e.eq_ignore_ascii_case("exr") => Ok(()),
        _ => Err(PathTraceError::Extension(path.to_path_buf())),
    }
}

/// The CPU reference path tracer (rayon over rows): `settings.spp` samples per pixel, summed
/// in sample order like the GPU's accumulation buffer.
pub fn render_pt_cpu(scene: &CpuScene, settings: &PtSettings) -> Result<PtImage, PathTraceError> {
    let (dag, index) = (scene.dag, scene.index);
    if index.node_voxels.len() != dag.words.len() {
        return Err(RenderError::IndexMismatch {
            index: index.node_voxels.len(),
            words: dag.words.len(),
        }
        .into());
    }
    let pt = settings.params()?;
    let p = RenderParams::with_colors(&settings.render, dag, scene.colors.len())?;
    let lut = srgb_lut();
    let (w, h) = (
        settings.render.width as usize,
        settings.render.height as usize,
    );
    let mut accum = vec![[0.0f32; 4]; w * h];
    let mut first_hits = vec![FirstHit::default(); w * h];
    let rays = accum
        .par_chunks_mut(w)
        .zip(first_hits.par_chunks_mut(w))
        .enumerate()
        .map(|(y, (row, row_hits))| {
            let mut rays = 0;
            for x in 0..w {
                let pixel = [x as u32, y as u32];
                for s in 0..settings.spp {
                    let first = (s == 0).then_some(&mut row_hits[x]);
                    let (l, n) = trace_path(scene, &p, &pt, &lut, pixel, s, first);
                    rays += n;
                    let a = &mut row[x];
                    *a = [a[0] + l[0], a[1] + l[1], a[2] + l[2], a[3] + 1.0];
                }
            }
            rays
        })
        .sum();
    Ok(PtImage {
        width: settings.render.width,
        height: settings.render.height,
        spp: settings.spp,
        accum,
        first_hits,
        rays: Some(rays),
    })
}
