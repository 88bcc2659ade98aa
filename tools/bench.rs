//! `voxdag bench ...`: benchmarks writing JSON plus a Markdown table (never timed unit tests).

mod colors;
mod compress;
mod edit;
mod hash;
mod ooc;
mod pathtrace;
mod primitives;
mod render_formats;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use serde::{Deserialize, Serialize};
use voxdag::atomic_file::write_atomic;
use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{render_cpu, Camera, RenderSettings};
use voxdag::scene::{self, ImportOptions};

use crate::commands::{
    check_output, peak_rss_bytes, progress_bar, read_json, seconds, write_json, BuildReport,
};

/// The benchmarks.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// Voxelize + SVDAG build per scene and resolution: times, peak RSS, voxels, SVO vs SVDAG nodes and bytes.
    Build(BenchBuildArgs),
    /// Primary-ray throughput of the GPU renderer vs the CPU ray cast on the same scene, in one run.
    Render(BenchRenderArgs),
    /// Tables 3.2-3.4: unique elements per transform set, encoded bytes, stage times, peak RSS.
    Compress(compress::BenchCompressArgs),
    /// Table 4.2: GPU slab hash tables (fill, search at 25/50/75% hits, insert) vs a CPU baseline.
    Hash(hash::BenchHashArgs),
    /// Table 5.1 / Figure 5.6: colour codecs' size, RMSE and encode time; GPU lossless throughput.
    Colors(colors::BenchColorsArgs),
    /// Figures 6.2/6.3: out-of-core path tracing, disk bytes and batching events with/without proxies.
    Ooc(ooc::BenchOocArgs),
    /// GPU primitives (scan, compaction, radix sort) vs their CPU references in the same run.
    Primitives(primitives::BenchPrimitivesArgs),
    /// Path tracing: ms per sample of the megakernel and wavefront GPU tracers vs the CPU reference.
    Pathtrace(pathtrace::BenchPathtraceArgs),
    /// Figure 4.8: GPU edit pipeline per-kernel times and bytes per table layout vs the CPU editor.
    Edit(edit::BenchEditArgs),
}

/// Arguments of `voxdag bench build`.
#[derive(Args)]
pub struct BenchBuildArgs {
    /// Scenes: names in the shared data set (bunny, dragon, buddha, horse, teapot, sponza-crytek,
    /// sponza-dabrovic) or paths to scene files.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "bunny,dragon,sponza-crytek"
    )]
    scenes: Vec<String>,
    /// Grid resolutions.
    #[arg(long, value_delimiter = ',', default_value = "2048,8192")]
    resolutions: Vec<u32>,
    /// Folder of the shared data set.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data"))]
    data: PathBuf,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-build.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-build.md")]
    markdown: PathBuf,
}

/// Arguments of `voxdag bench render`.
#[derive(Args)]
pub struct BenchRenderArgs {
    /// Scene: a .vdag file, a scene file, or a shared data set name (default: bunny, else the bundled avocado).
    scene: Option<String>,
    /// Resolution used when the scene must be built first.
    #[arg(long, default_value_t = 2048)]
    resolution: u32,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "1024x1024", value_parser = crate::commands::parse_size)]
    size: (u32, u32),
    /// Folder of the shared data set.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data"))]
    data: PathBuf,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-render.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-render.md")]
    markdown: PathBuf,
    /// Also time these DAG formats, traversed directly, against svdag32 in the same run
    /// (comma-separated: ssvdag, tsvdag-sa-base, tsvdag-sa-lut, tsvdag-sa-huffman,
    /// tsvdag-sat-base, tsvdag-sat-lut, tsvdag-sat-huffman).
    #[arg(long, value_delimiter = ',')]
    formats: Vec<String>,
    /// Frames timed per format (the median is reported).
    #[arg(long, default_value_t = 5)]
    frames: u32,
}

/// Runs one benchmark.
pub fn run(command: BenchCommand, quiet: bool) -> Result<()> {
    let outputs: Vec<&Path> = match &command {
        BenchCommand::Build(args) => vec![args.json.as_path(), args.markdown.as_path()],
        BenchCommand::Render(args) => vec![args.json.as_path(), args.markdown.as_path()],
        BenchCommand::Compress(args) => args.outputs(),
        BenchCommand::Hash(args) => args.outputs(),
        BenchCommand::Colors(args) => args.outputs(),
        BenchCommand::Primitives(args) => args.outputs(),
        BenchCommand::Ooc(args) => args.outputs(),
        BenchCommand::Pathtrace(args) => args.outputs(),
        BenchCommand::Edit(args) => args.outputs(),
    };
    check_outputs(&outputs)?;
    match command {
        BenchCommand::Build(args) => bench_build(&args),
        BenchCommand::Render(args) => bench_render(&args, quiet),
        BenchCommand::Compress(args) => compress::bench_compress(&args),
        BenchCommand::Hash(args) => hash::bench_hash(&args, quiet),
        BenchCommand::Colors(args) => colors::bench_colors(&args),
        BenchCommand::Primitives(args) => primitives::bench_primitives(&args),
        BenchCommand::Ooc(args) => ooc::bench_ooc(&args, quiet),
        BenchCommand::Pathtrace(args) => pathtrace::bench_pathtrace(&args),
        BenchCommand::Edit(args) => edit::bench_edit(&args),
    }
}

/// Checks every output path before a benchmark starts (hours of work must not end in "cannot
/// write"): their folders are created as the writers would, then each path is checked.
fn check_outputs(paths: &[&Path]) -> Result<()> {
    for path in paths {
        if let Some(dir) = path
            .parent()
            .filter(|d| !d.as_os_str().is_empty() && !d.is_dir())
        {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        check_output(path)?;
    }
    Ok(())
}

/// The middle value of `v` (the upper one of an even count; 0 for none).
fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.get(s.len() / 2).copied().unwrap_or(0.0)
}

/// Resolves a scene name of the shared data set, or takes the argument as a path.
fn scene_path(data: &Path, name: &str) -> Result<PathBuf> {
    let known = match name {
        "bunny" | "dragon" | "buddha" | "horse" | "teapot" | "sponza-dabrovic" => {
            format!("meshes/{name}.obj")
        }
        "sponza-crytek" => "meshes/sponza-crytek/sponza_crytek_noleaf.obj".to_string(),
        _ => return Ok(PathBuf::from(name)),
    };
    let path = data.join(known);
    if !path.exists() {
        bail!(
            "scene {name}: {} not found (pass --data DIR)",
            path.display()
        );
    }
    Ok(path)
}

/// One row of `bench build`: a build report plus the scene name.
#[derive(Serialize, Deserialize)]
struct BuildRow {
    scene: String,
    #[serde(flatten)]
    report: serde_json::Value,
}

/// Runs `voxdag build INPUT -r RESOLUTION -o OUT --report REPORT` (without colours when
/// `no_colors`) in a child process, so that the report's peak RSS is the build's own.
fn run_build(
    input: &Path,
    resolution: u32,
    out: &Path,
    report: &Path,
    no_colors: bool,
) -> Result<serde_json::Value> {
    let exe = std::env::current_exe().context("locating the voxdag executable")?;
    let mut build = Command::new(&exe);
    build
        .arg("build")
        .arg(input)
        .args(["--resolution", &resolution.to_string(), "-o"])
        .arg(out)
        .arg("--report")
        .arg(report);
    if no_colors {
        build.arg("--no-colors");
    }
    let status = build.status().context("starting voxdag build")?;
    if !status.success() {
        bail!(
            "voxdag build {} at {resolution} failed ({status})",
            input.display()
        );
    }
    read_json(report)
}

/// `voxdag bench build`: each build runs in a child process so that its peak RSS is its own.
fn bench_build(args: &BenchBuildArgs) -> Result<()> {
    let scratch = tempfile::Builder::new().prefix("voxdag-bench").tempdir()?;
    let mut rows = Vec::new();
    for name in &args.scenes {
        let input = scene_path(&args.data, name)?;
        for &resolution in &args.resolutions {
            eprintln!("bench build: {name} at {resolution}^3");
            let out = scratch.path().join("scene.vdag");
            let report_path = scratch.path().join("report.json");
            let report = run_build(&input, resolution, &out, &report_path, false)?;
            rows.push(BuildRow {
                scene: name.clone(),
                report,
            });
            std::fs::remove_file(&out).ok();
        }
    }
    let mut md = String::from(
        "| scene | N | voxels | voxelize s | build s | total s | peak RSS MiB | SVO nodes | SVDAG nodes | SVO bytes | SVDAG bytes |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for row in &rows {
        let r = &row.report;
        let report: BuildReport = serde_json::from_value(r.clone())?;
        let svo: u64 = report.stats.levels.iter().map(|l| l.svo).sum();
        let svdag: u64 = report.stats.levels.iter().map(|l| l.svdag).sum();
        md += &format!(
            "| {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.0} | {} | {} | {} | {} |\n",
            row.scene,
            report.resolution,
            report.voxels,
            report.voxelize_s,
            report.build_s,
            report.voxelize_s + report.build_s,
            report.peak_rss_bytes as f64 / 1048576.0,
            svo,
            svdag,
            report.stats.bytes.svo,
            report.stats.bytes.svdag32
        );
    }
    print!("{md}");
    write_outputs(&args.json, &rows, &args.markdown, &md)
}

/// Result of `bench render`.
#[derive(Serialize)]
struct RenderBench {
    scene: String,
    resolution: u32,
    width: u32,
    height: u32,
    device: String,
    gpu_pass_ms: f64,
    gpu_wall_ms: f64,
    gpu_mrays_s: f64,
    cpu_ms: f64,
    cpu_threads: usize,
    cpu_mrays_s: f64,
    gpu_over_cpu: f64,
    hit_mask_mismatch_pixels: usize,
    /// Per DAG format (`--formats`), svdag32 first.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    formats: Vec<render_formats::FormatBench>,
}

/// `voxdag bench render`: 1 primary ray per pixel, no shadows, on both renderers.
fn bench_render(args: &BenchRenderArgs, quiet: bool) -> Result<()> {
    let name = args.scene.clone().unwrap_or_else(|| {
        if args.data.join("meshes/bunny.obj").exists() {
            "bunny".into()
        } else {
            concat!(env!("CARGO_MANIFEST_DIR"), "/assets/avocado/Avocado.gltf").into()
        }
    });
    let path = scene_path(&args.data, &name)?;
    let dag = if path.extension().is_some_and(|e| e == "vdag") {
        Svdag::load(&path)?
    } else {
        let options = ImportOptions {
            resolution: Some(args.resolution),
            ..Default::default()
        };
        let bar = progress_bar(quiet);
        let voxels = scene::import(&path, &options, &bar)?;
        bar.finish_and_clear();
        Svdag::from_voxels(&voxels)?
    };
    let mut settings = RenderSettings::new(args.size.0, args.size.1, Camera::frame(&dag));
    settings.shadows = false;
    let rays = (args.size.0 * args.size.1) as f64;

    let context = GpuContext::new(&GpuOptions::default())?;
    let renderer = GpuRenderer::new(&context)?;
    let scene = renderer.upload(&dag)?;
    // Warm-up (pipeline compilation, first-touch of memory), then the measured run.
    renderer.render(&scene, &settings, None)?;
    let mut profiler = Profiler::new(&context)?;
    let start = Instant::now();
    let gpu_image = renderer.render(&scene, &settings, Some(&mut profiler))?;
    let gpu_wall = start.elapsed();
    let gpu_pass_ms: f64 = profiler
        .passes()
        .iter()
        .filter(|p| p.name == "primary rays")
        .map(|p| p.gpu_ms)
        .sum();
    let device = context.info().name.clone();
    drop(scene);
    drop(renderer);
    drop(profiler);
    let formats = if args.formats.is_empty() {
        Vec::new()
    } else {
        render_formats::bench_formats(&context, &dag, &args.formats, &settings, args.frames)?
    };
    drop(context);

    let index = VoxelIndex::new(&dag);
    let start = Instant::now();
    let cpu_image = render_cpu(&dag, &index, &settings)?;
    let cpu_time = start.elapsed();
    let mismatch = gpu_image
        .hits
        .iter()
        .zip(&cpu_image.hits)
        .filter(|(a, b)| a != b)
        .count();

    let cpu_ms = cpu_time.as_secs_f64() * 1e3;
    let result = RenderBench {
        scene: name,
        resolution: dag.resolution,
        width: args.size.0,
        height: args.size.1,
        device,
        gpu_pass_ms,
        gpu_wall_ms: gpu_wall.as_secs_f64() * 1e3,
        gpu_mrays_s: rays / gpu_pass_ms / 1e3,
        cpu_ms,
        cpu_threads: rayon::current_num_threads(),
        cpu_mrays_s: rays / cpu_ms / 1e3,
        gpu_over_cpu: cpu_ms / gpu_pass_ms,
        hit_mask_mismatch_pixels: mismatch,
        formats,
    };
    let mut md = format!(
        "| scene | N | image | device | GPU pass ms | GPU Mrays/s | CPU ms ({} threads) | CPU Mrays/s | GPU/CPU |\n|---|---|---|---|---|---|---|---|---|\n| {} | {} | {}x{} | {} | {:.1} | {:.2} | {:.1} | {:.2} | {:.2}x |\n",
        result.cpu_threads,
        result.scene,
        result.resolution,
        result.width,
        result.height,
        result.device,
        result.gpu_pass_ms,
        result.gpu_mrays_s,
        result.cpu_ms,
        result.cpu_mrays_s,
        result.gpu_over_cpu
    );
    if !result.formats.is_empty() {
        md.push_str(&render_formats::markdown(&result.formats, args.frames));
    }
    print!("{md}");
    eprintln!(
        "peak RSS {:.0} MiB, GPU wall {}",
        peak_rss_bytes() as f64 / 1048576.0,
        seconds(gpu_wall)
    );
    write_outputs(&args.json, &result, &args.markdown, &md)
}

/// Writes the JSON and Markdown outputs of a benchmark, creating their folders.
fn write_outputs(json: &Path, value: &impl Serialize, markdown: &Path, md: &str) -> Result<()> {
    for path in [json, markdown] {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
    }
    write_json(json, value)?;
    write_atomic(markdown, |w| w.write_all(md.as_bytes()))
        .with_context(|| format!("writing {}", markdown.display()))?;
    eprintln!("wrote {} and {}", json.display(), markdown.display());
    Ok(())
}
