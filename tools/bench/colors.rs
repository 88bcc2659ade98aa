//! `voxdag bench colors`: the dissertation's Table 5.1 and Figure 5.6 for our scenes — per scene,
//! resolution and codec the encode time, the size as a percentage of raw RGB888 and the RMSE —
//! plus the GPU lossless encoder's throughput against the CPU reference in the same run. Every
//! result is verified (exact codecs exact, lossy within the threshold); a failure exits non-zero.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use image::{Rgb, RgbImage};
use indicatif::ProgressBar;
use serde::{Deserialize, Serialize};
use voxdag::attr::chunks::chunk_sizes;
use voxdag::attr::{
    lossless, max_channel_error, rmse, varbit, ChunkedColors, ColorCodec, LosslessVariant,
};
use voxdag::attr_gpu::lossless::LosslessGpu;
use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::scene::{self, morton, ImportOptions, Voxels};

use super::write_outputs;

/// Arguments of `voxdag bench colors`.
#[derive(Args)]
pub struct BenchColorsArgs {
    /// Textured scenes (default: every model of ../shared/data/textured that loads).
    #[arg(long, value_delimiter = ',')]
    inputs: Vec<PathBuf>,
    /// Grid resolutions.
    #[arg(long, value_delimiter = ',', default_value = "512,1024")]
    resolutions: Vec<u32>,
    /// Per-channel error threshold of the lossy codecs (colours in [0, 1]).
    #[arg(long, default_value_t = voxdag::attr::DEFAULT_THRESHOLD)]
    threshold: f32,
    /// Chunk depth below the root for every codec (default: each codec's own: nodes of 256^3 exact, 128^3 lossy).
    #[arg(long)]
    chunk_depth: Option<u32>,
    /// Leave out the Perlin-noise-painted terrain.
    #[arg(long)]
    no_perlin: bool,
    /// Leave out the offline Dolonius encoder (minutes at high resolutions).
    #[arg(long)]
    no_dolonius: bool,
    /// Leave out the GPU lossless encoder.
    #[arg(long)]
    no_gpu: bool,
    /// Folder of the shared data set.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data"))]
    data: PathBuf,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-colors.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-colors.md")]
    markdown: PathBuf,
    /// RMSE-vs-size scatter plot (PNG, Figure 5.6).
    #[arg(long, default_value = "out/bench-colors.png")]
    chart: PathBuf,
}

impl BenchColorsArgs {
    /// The output files, checked before the work starts.
    pub(super) fn outputs(&self) -> Vec<&std::path::Path> {
        vec![
            self.json.as_path(),
            self.markdown.as_path(),
            self.chart.as_path(),
        ]
    }
}

/// One codec on one scene at one resolution.
#[derive(Serialize, Deserialize, Clone)]
struct CodecRow {
    scene: String,
    resolution: u32,
    voxels: u64,
    codec: String,
    chunk_depth: u32,
    chunks: u64,
    encode_s: f64,
    bytes: u64,
    percent_of_rgb888: f64,
    rmse: f64,
    max_channel_error: f32,
    verified: bool,
}

/// The GPU lossless encoder against the CPU reference on one colour array.
#[derive(Serialize, Deserialize)]
struct GpuRow {
    scene: String,
    resolution: u32,
    colors: u64,
    gpu_ms: f64,
    gpu_mcolors_per_s: f64,
    cpu_ms: f64,
    cpu_mcolors_per_s: f64,
    identical_bytes: bool,
}

/// Everything the bench writes as JSON.
#[derive(Serialize, Deserialize)]
struct ColorsReport {
    threshold: f32,
    device: Option<String>,
    rows: Vec<CodecRow>,
    gpu: Vec<GpuRow>,
}

/// The codecs of Table 5.1, in table order.
fn codecs(threshold: f32, dolonius: bool) -> Vec<ColorCodec> {
    let mut list = vec![ColorCodec::Lossy { threshold }];
    if dolonius {
        list.push(ColorCodec::Dolonius { threshold });
    }
    list.extend([
        ColorCodec::Lossless(LosslessVariant::Rgb888),
        ColorCodec::Lossless(LosslessVariant::Rgb565),
        ColorCodec::Dado,
        ColorCodec::Raw,
    ]);
    list
}

/// The textured models of the shared data set (glTF files and spot's OBJ).
fn default_inputs(data: &Path) -> Vec<PathBuf> {
    let dir = data.join("textured");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut inputs: Vec<PathBuf> = entries
        .filter_map(|e| {
            let folder = e.ok()?.path();
            std::fs::read_dir(&folder)
                .ok()?
                .filter_map(|f| f.ok().map(|f| f.path()))
                .find(|p| {
                    matches!(
                        p.extension().and_then(|e| e.to_str()),
                        Some("gltf" | "glb" | "obj")
                    )
                })
        })
        .collect();
    inputs.sort();
    inputs
}

/// Voxelizes a textured scene (spot's OBJ gets its PNG as texture).
fn voxelize(input: &Path, resolution: u32) -> Result<Voxels> {
    let png = input.with_file_name("spot_texture.png");
    let texture =
        (input.extension().and_then(|e| e.to_str()) == Some("obj") && png.exists()).then_some(png);
    let options = ImportOptions {
        resolution: Some(resolution),
        texture_override: texture,
        ..Default::default()
    };
    Ok(scene::import(input, &options, &ProgressBar::hidden())?)
}

/// Improved Perlin noise (Perlin 2002) with a permutation table shuffled by a fixed seed.
struct Perlin {
    perm: [u8; 512],
}

impl Perlin {
    fn new(seed: u64) -> Perlin {
        let mut p: Vec<u8> = (0..=255).collect();
        let mut state = seed;
        for i in (1..256).rev() {
            // SplitMix64 steps: a fixed, portable shuffle.
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            p.swap(i, ((z ^ (z >> 31)) % (i as u64 + 1)) as usize);
        }
        let mut perm = [0u8; 512];
        for i in 0..512 {
            perm[i] = p[i & 255];
        }
        Perlin { perm }
    }

    fn grad(hash: u8, x: f32, y: f32, z: f32) -> f32 {
        let h = hash & 15;
        let u = if h < 8 { x } else { y };
        let v = if h < 4 {
            y
        } else if h == 12 || h == 14 {
            x
        } else {
            z
        };
        (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
    }

    /// Noise in about [-1, 1] at a point.
    fn noise(&self, x: f32, y: f32, z: f32) -> f32 {
        let fade = |t: f32| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
        let lerp = |t: f32, a: f32, b: f32| a + t * (b - a);
        let (xf, yf, zf) = (x.floor(), y.floor(), z.floor());
        let (xi, yi, zi) = (
            (xf as i32 & 255) as usize,
            (yf as i32 & 255) as usize,
            (zf as i32 & 255) as usize,
        );
        let (x, y, z) = (x - xf, y - yf, z - zf);
        let (u, v, w) = (fade(x), fade(y), fade(z));
        let p = &self.perm;
        let a = p[xi] as usize + yi;
        let (aa, ab) = (p[a] as usize + zi, p[a + 1] as usize + zi);
        let b = p[xi + 1] as usize + yi;
        let (ba, bb) = (p[b] as usize + zi, p[b + 1] as usize + zi);
        let g = |h: usize, dx: f32, dy: f32, dz: f32| Perlin::grad(p[h], x - dx, y - dy, z - dz);
        lerp(
            w,
            lerp(
                v,
                lerp(u, g(aa, 0.0, 0.0, 0.0), g(ba, 1.0, 0.0, 0.0)),
                lerp(u, g(ab, 0.0, 1.0, 0.0), g(bb, 1.0, 1.0, 0.0)),
            ),
            lerp(
                v,
                lerp(u, g(aa + 1, 0.0, 0.0, 1.0), g(ba + 1, 1.0, 0.0, 1.0)),
                lerp(u, g(ab + 1, 0.0, 1.0, 1.0), g(bb + 1, 1.0, 1.0, 1.0)),
            ),
        )
    }

    /// Four octaves of noise, about [-1, 1].
    fn fbm(&self, x: f32, y: f32, z: f32) -> f32 {
        let (mut sum, mut amp, mut freq) = (0.0, 0.5, 1.0);
        for _ in 0..4 {
            sum += amp * self.noise(x * freq, y * freq, z * freq);
            amp *= 0.5;
            freq *= 2.0;
        }
        sum
    }
}

/// A generated terrain (a 3-voxel-thick height-field shell) painted by 3D Perlin noise: smooth
/// but never constant colours, the hard case of §5.3.
fn perlin_terrain(resolution: u32) -> Voxels {
    let (shape, paint) = (Perlin::new(1), Perlin::new(2));
    let n = resolution as f32;
    let mut voxels: Vec<(u64, u32)> = Vec::new();
    for z in 0..resolution {
        for x in 0..resolution {
            let h = n * (0.35 + 0.25 * shape.fbm(x as f32 * 4.0 / n, 0.5, z as f32 * 4.0 / n));
            let top = (h.max(3.0) as u32).min(resolution - 1);
            for y in top - 2..=top {
                let p = [x, y, z].map(|v| v as f32 * 16.0 / n);
                let channel = |offset: f32| {
                    let v = 0.5 + 0.6 * paint.fbm(p[0] + offset, p[1], p[2]);
                    (v.clamp(0.0, 1.0) * 255.0).round() as u32
                };
                let c = channel(0.0) | channel(31.7) << 8 | channel(71.3) << 16 | 0xff00_0000;
                voxels.push((morton::encode(x, y, z), c));
            }
        }
    }
    voxels.sort_unstable();
    Voxels {
        resolution,
        codes: voxels.iter().map(|v| v.0).collect(),
        colors: voxels.iter().map(|v| v.1).collect(),
    }
}

/// Encodes, decodes and verifies one codec on one scene.
fn measure(
    scene: &str,
    dag: &Svdag,
    index: &VoxelIndex,
    codec: ColorCodec,
    chunk_depth: Option<u32>,
) -> Result<CodecRow> {
    let depth = chunk_depth
        .unwrap_or_else(|| codec.default_chunk_depth(dag.resolution))
        .min(dag.root_level());
    let sizes = chunk_sizes(dag, index, depth);
    let start = Instant::now();
    let chunks = ChunkedColors::encode(&dag.colors, &sizes, codec, depth, &ProgressBar::hidden())?;
    let encode_s = start.elapsed().as_secs_f64();
    let decoded = chunks.decode_all()?;
    let error = max_channel_error(&dag.colors, &decoded);
    let verified = decoded.len() == dag.colors.len()
        && match codec {
            ColorCodec::Lossy { threshold } | ColorCodec::Dolonius { threshold } => {
                error <= varbit::max_delta(threshold) as f32 / 255.0
            }
            other => error <= other.threshold(),
        };
    let voxels = dag.colors.len() as u64;
    Ok(CodecRow {
        scene: scene.to_string(),
        resolution: dag.resolution,
        voxels,
        codec: codec.name(),
        chunk_depth: depth,
        chunks: chunks.chunk_count() as u64,
        encode_s,
        bytes: chunks.byte_size(),
        percent_of_rgb888: 100.0 * chunks.byte_size() as f64 / (3 * voxels).max(1) as f64,
        rmse: rmse(&dag.colors, &decoded),
        max_channel_error: error,
        verified,
    })
}

/// GPU lossless encode of the whole colour array (GPU timestamps) against the CPU reference.
fn measure_gpu(
    ctx: &std::sync::Arc<GpuContext>,
    gpu: &LosslessGpu,
    scene: &str,
    dag: &Svdag,
) -> Result<GpuRow> {
    let mut profiler = Profiler::new(ctx)?;
    let words = gpu.encode_vec(&dag.colors, LosslessVariant::Rgb888, Some(&mut profiler))?;
    let gpu_ms: f64 = profiler.passes().iter().map(|p| p.gpu_ms).sum();
    let start = Instant::now();
    let reference = lossless::encode(&dag.colors, LosslessVariant::Rgb888);
    let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
    let colors = dag.colors.len() as u64;
    let rate = |ms: f64| colors as f64 / (ms * 1e3).max(1e-9);
    Ok(GpuRow {
        scene: scene.to_string(),
        resolution: dag.resolution,
        colors,
        gpu_ms,
        gpu_mcolors_per_s: rate(gpu_ms),
        cpu_ms,
        cpu_mcolors_per_s: rate(cpu_ms),
        identical_bytes: words == reference,
    })
}

/// `voxdag bench colors`.
pub fn bench_colors(args: &BenchColorsArgs) -> Result<()> {
    if !(args.threshold > 0.0 && args.threshold <= 1.0) {
        bail!("--threshold {} not in (0, 1]", args.threshold);
    }
    let inputs = if args.inputs.is_empty() {
        default_inputs(&args.data)
    } else {
        args.inputs.clone()
    };
    let mut scenes: Vec<(String, Option<PathBuf>)> = inputs
        .iter()
        .map(|p| {
            let name = p.file_stem().and_then(|s| s.to_str()).unwrap_or("scene");
            (
                name.trim_end_matches("_triangulated").to_string(),
                Some(p.clone()),
            )
        })
        .collect();
    if !args.no_perlin {
        scenes.push(("perlin-terrain".into(), None));
    }
    let gpu = if args.no_gpu {
        None
    } else {
        let ctx = GpuContext::new(&GpuOptions::default())?;
        let encoder = LosslessGpu::new(&ctx)?;
        Some((ctx, encoder))
    };
    let mut report = ColorsReport {
        threshold: args.threshold,
        device: gpu.as_ref().map(|(ctx, _)| ctx.info().name.clone()),
        rows: Vec::new(),
        gpu: Vec::new(),
    };
    for (name, input) in &scenes {
        for &resolution in &args.resolutions {
            let voxels = match input {
                Some(path) => match voxelize(path, resolution) {
                    Ok(v) => v,
                    Err(e) if args.inputs.is_empty() => {
                        eprintln!("bench colors: skipping {name}: {e:#}");
                        break;
                    }
                    Err(e) => return Err(e).with_context(|| format!("voxelizing {name}")),
                },
                None => perlin_terrain(resolution),
            };
            if voxels.colors.is_empty() {
                eprintln!("bench colors: skipping {name}: no colours");
                break;
            }
            let dag = Svdag::from_voxels(&voxels)?;
            drop(voxels);
            let index = VoxelIndex::new(&dag);
            eprintln!(
                "bench colors: {name} at {resolution}^3, {} colours",
                dag.colors.len()
            );
            for codec in codecs(args.threshold, !args.no_dolonius) {
                let row = measure(name, &dag, &index, codec, args.chunk_depth)?;
                eprintln!(
                    "  {:<14} {:>8.3} s {:>6.1}% RMSE {:.4}{}",
                    row.codec,
                    row.encode_s,
                    row.percent_of_rgb888,
                    row.rmse,
                    if row.verified { "" } else { "  VERIFY FAILED" }
                );
                report.rows.push(row);
            }
            if let Some((ctx, encoder)) = &gpu {
                if dag.colors.len() as u64 <= u32::MAX as u64 {
                    report.gpu.push(measure_gpu(ctx, encoder, name, &dag)?);
                }
            }
        }
    }
    let md = markdown(&report);
    print!("{md}");
    write_chart(&args.chart, &report.rows)?;
    write_outputs(&args.json, &report, &args.markdown, &md)?;
    let failed: Vec<String> = report
        .rows
        .iter()
        .filter(|r| !r.verified)
        .map(|r| format!("{} {} at {}", r.codec, r.scene, r.resolution))
        .chain(
            report
                .gpu
                .iter()
                .filter(|g| !g.identical_bytes)
                .map(|g| format!("GPU lossless on {} at {}", g.scene, g.resolution)),
        )
        .collect();
    if !failed.is_empty() {
        bail!("verification failed: {}", failed.join(", "));
    }
    Ok(())
}

/// Table 5.1 (per scene and resolution, one column group per codec) and the GPU table.
fn markdown(report: &ColorsReport) -> String {
    let mut md = format!(
        "### Colour compression (Table 5.1), threshold {}\n\n\
         | scene | res | colours | codec | depth | chunks | encode s | % of RGB888 | RMSE | max err | ok |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
        report.threshold
    );
    for r in &report.rows {
        md += &format!(
            "| {} | {} | {} | {} | {} | {} | {:.3} | {:.1} | {:.4} | {:.4} | {} |\n",
            r.scene,
            r.resolution,
            r.voxels,
            r.codec,
            r.chunk_depth,
            r.chunks,
            r.encode_s,
            r.percent_of_rgb888,
            r.rmse,
            r.max_channel_error,
            if r.verified { "yes" } else { "**NO**" }
        );
    }
    // Lossy vs offline speed-up per scene, where both ran.
    let speedups: Vec<String> = report
        .rows
        .iter()
        .filter(|r| r.codec.starts_with("lossy"))
        .filter_map(|lossy| {
            let offline = report.rows.iter().find(|r| {
                r.codec.starts_with("dolonius")
                    && r.scene == lossy.scene
                    && r.resolution == lossy.resolution
            })?;
            Some(format!(
                "{} {}: {:.0}x",
                lossy.scene,
                lossy.resolution,
                offline.encode_s / lossy.encode_s.max(1e-9)
            ))
        })
        .collect();
    if !speedups.is_empty() {
        md += &format!(
            "\nOurs-lossy encode speed-up over the offline Dolonius encoder: {}\n",
            speedups.join(", ")
        );
    }
    if !report.gpu.is_empty() {
        md += &format!(
            "\n### Lossless RGB888 encode, GPU ({}) vs CPU reference (single chunk, same run)\n\n\
             | scene | res | colours | GPU ms | GPU Mcol/s | CPU ms | CPU Mcol/s | identical |\n\
             |---|---|---|---|---|---|---|---|\n",
            report.device.as_deref().unwrap_or("?")
        );
        for g in &report.gpu {
            md += &format!(
                "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {} |\n",
                g.scene,
                g.resolution,
                g.colors,
                g.gpu_ms,
                g.gpu_mcolors_per_s,
                g.cpu_ms,
                g.cpu_mcolors_per_s,
                if g.identical_bytes { "yes" } else { "**NO**" }
            );
        }
    }
    md
}

/// Colour of each codec's points in the chart, in `codecs` order by name prefix.
const POINT_COLOURS: [(&str, [u8; 3]); 6] = [
    ("lossy", [219, 68, 55]),
    ("dolonius", [244, 160, 0]),
    ("lossless565", [66, 133, 244]),
    ("lossless", [15, 157, 88]),
    ("dado", [171, 71, 188]),
    ("raw", [90, 90, 90]),
];

/// Figure 5.6: RMSE (y, up) against size in % of RGB888 (x), one filled square per row; axes
/// from 0 to the largest value of each.
fn write_chart(path: &Path, rows: &[CodecRow]) -> Result<()> {
    let (w, h, margin) = (640u32, 400u32, 30u32);
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let max_x = rows.iter().map(|r| r.percent_of_rgb888).fold(1.0, f64::max);
    let max_y = rows.iter().map(|r| r.rmse).fold(1e-3, f64::max);
    let (plot_w, plot_h) = (w - 2 * margin, h - 2 * margin);
    for x in margin..w - margin {
        img.put_pixel(x, h - margin, Rgb([0, 0, 0]));
    }
    for y in margin..=h - margin {
        img.put_pixel(margin, y, Rgb([0, 0, 0]));
    }
    // Tick marks every 10% of size and every 0.01 RMSE.
    let mut pct = 0.0;
    while pct <= max_x {
        let x = margin + (plot_w as f64 * pct / max_x) as u32;
        for y in h - margin..h - margin + 5 {
            img.put_pixel(x.min(w - 1), y, Rgb([0, 0, 0]));
        }
        pct += 10.0;
    }
    let mut e = 0.0;
    while e <= max_y {
        let y = h - margin - (plot_h as f64 * e / max_y) as u32;
        for x in margin - 5..margin {
            img.put_pixel(x, y, Rgb([0, 0, 0]));
        }
        e += 0.01;
    }
    for r in rows {
        let colour = POINT_COLOURS
            .iter()
            .find(|(name, _)| r.codec.starts_with(name))
            .map_or([0, 0, 0], |(_, c)| *c);
        let cx = margin + (plot_w as f64 * r.percent_of_rgb888 / max_x) as u32;
        let cy = h - margin - (plot_h as f64 * r.rmse / max_y) as u32;
        for x in cx.saturating_sub(3)..=(cx + 3).min(w - 1) {
            for y in cy.saturating_sub(3)..=(cy + 3).min(h - 1) {
                img.put_pixel(x, y, Rgb(colour));
            }
        }
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    voxdag::atomic_file::write_atomic(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .with_context(|| format!("writing {}", path.display()))
}
