//! `voxdag bench pathtrace`: time per sample of the megakernel and wavefront GPU path tracers
//! against the CPU reference path tracer (rayon, all cores) in the same run, and rays per
//! second (rays = camera + bounce + shadow rays, counted by the CPU reference, which traces the
//! same paths). GPU time is the sum of the profiled passes of each sample.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use serde::Serialize;
use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::render::cpu::ColorSource;
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::pathtrace::{render_pt_cpu, CpuScene, PtImage, PtSettings};
use voxdag::render::pathtrace_gpu::{GpuPathTracer, PtMode};
use voxdag::render::{Camera, RenderSettings};
use voxdag::scene::{self, ImportOptions};

use super::{scene_path, write_outputs};
use crate::commands::progress_bar;

/// Arguments of `voxdag bench pathtrace`.
#[derive(Args)]
pub struct BenchPathtraceArgs {
    /// Scenes: shared data set names or scene files.
    #[arg(long, value_delimiter = ',', default_value = "bunny,dragon")]
    scenes: Vec<String>,
    /// Grid resolutions.
    #[arg(long, value_delimiter = ',', default_value = "512")]
    resolutions: Vec<u32>,
    /// Image size WIDTHxHEIGHT (the table is 1920x1080).
    #[arg(long, default_value = "320x180", value_parser = crate::commands::parse_size)]
    size: (u32, u32),
    /// Samples per pixel timed per tracer.
    #[arg(long, default_value_t = 4)]
    spp: u32,
    /// Surface interactions per path.
    #[arg(long, default_value_t = 4)]
    bounces: u32,
    /// Folder of the shared data set.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data"))]
    data: PathBuf,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-pathtrace.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-pathtrace.md")]
    markdown: PathBuf,
}

impl BenchPathtraceArgs {
    /// The output files, checked before the work starts.
    pub(super) fn outputs(&self) -> Vec<&std::path::Path> {
        vec![self.json.as_path(), self.markdown.as_path()]
    }
}

/// One scene at one resolution.
#[derive(Serialize)]
struct PathtraceRow {
    scene: String,
    resolution: u32,
    width: u32,
    height: u32,
    spp: u32,
    bounces: u32,
    rays_per_sample: u64,
    mega_ms_per_sample: f64,
    wave_ms_per_sample: f64,
    cpu_ms_per_sample: f64,
    cpu_threads: usize,
    mega_mrays_s: f64,
    wave_mrays_s: f64,
    cpu_mrays_s: f64,
    /// CPU time / megakernel time (target >= 0.5 on lavapipe, same cores).
    mega_over_cpu: f64,
    /// CPU time / wavefront time.
    wave_over_cpu: f64,
    /// Mean absolute linear pixel difference, megakernel vs CPU (sanity: same paths).
    mega_cpu_mean_abs_diff: f64,
}

/// The whole run.
#[derive(Serialize)]
struct PathtraceReport {
    device: String,
    rows: Vec<PathtraceRow>,
    /// Per-pass GPU tables of the profiler, per scene and tracer (where the time goes).
    passes: String,
}

fn mean_abs_diff(a: &PtImage, b: &PtImage) -> f64 {
    let (la, lb) = (a.linear(), b.linear());
    la.iter()
        .zip(&lb)
        .map(|(x, y)| (x - y).abs() as f64)
        .sum::<f64>()
        / la.len().max(1) as f64
}

/// Runs the benchmark.
pub fn bench_pathtrace(args: &BenchPathtraceArgs) -> Result<()> {
    if args.spp == 0 {
        bail!("--spp must be at least 1");
    }
    let ctx = GpuContext::new(&GpuOptions::default())?;
    let renderer = GpuRenderer::new(&ctx)?;
    let tracer = GpuPathTracer::new(&ctx)?;
    let mut passes = String::new();
    let mut rows = Vec::new();
    for name in &args.scenes {
        let path = scene_path(&args.data, name)?;
        for &resolution in &args.resolutions {
            let dag = if path.extension().is_some_and(|e| e == "vdag") {
                Svdag::load(&path)?
            } else {
                let options = ImportOptions {
                    resolution: Some(resolution),
                    ..Default::default()
                };
                let bar = progress_bar(true);
                Svdag::from_voxels(&scene::import(&path, &options, &bar)?)?
            };
            let (w, h) = args.size;
            let mut s = PtSettings::new(RenderSettings::new(w, h, Camera::frame(&dag)));
            s.spp = args.spp;
            s.bounces = args.bounces;
            let scene = renderer.upload(&dag)?;
            let mut warm = s;
            warm.spp = 1;
            let mut gpu_ms = |mode: PtMode| -> Result<(f64, PtImage)> {
                // Warm-up: pipelines, first touch of the buffers.
                tracer.render(&scene, &warm, mode, None)?;
                let mut profiler = Profiler::new(&ctx)?;
                let image = tracer.render(&scene, &s, mode, Some(&mut profiler))?;
                let ms: f64 = profiler.passes().iter().map(|p| p.gpu_ms).sum();
                passes.push_str(&format!(
                    "{name} N={resolution} {mode:?}:\n{}",
                    profiler.table()
                ));
                Ok((ms / s.spp as f64, image))
            };
            let (mega_ms, mega) = gpu_ms(PtMode::Megakernel)?;
            let (wave_ms, _) = gpu_ms(PtMode::Wavefront)?;
            let index = VoxelIndex::new(&dag);
            let cpu_scene = CpuScene {
                dag: &dag,
                index: &index,
                colors: ColorSource::Raw(&dag.colors),
            };
            let start = Instant::now();
            let cpu = render_pt_cpu(&cpu_scene, &s)?;
            let cpu_ms = start.elapsed().as_secs_f64() * 1e3 / s.spp as f64;
            let rays = cpu.rays.unwrap_or(0) / s.spp as u64;
            let mrays = |ms: f64| rays as f64 / ms / 1e3;
            rows.push(PathtraceRow {
                scene: name.clone(),
                resolution: dag.resolution,
                width: w,
                height: h,
                spp: s.spp,
                bounces: s.bounces,
                rays_per_sample: rays,
                mega_ms_per_sample: mega_ms,
                wave_ms_per_sample: wave_ms,
                cpu_ms_per_sample: cpu_ms,
                cpu_threads: rayon::current_num_threads(),
                mega_mrays_s: mrays(mega_ms),
                wave_mrays_s: mrays(wave_ms),
                cpu_mrays_s: mrays(cpu_ms),
                mega_over_cpu: cpu_ms / mega_ms,
                wave_over_cpu: cpu_ms / wave_ms,
                mega_cpu_mean_abs_diff: mean_abs_diff(&mega, &cpu),
            });
            eprintln!("{name} {resolution}: done");
        }
    }
    let info = ctx.info();
    let mut md = format!(
        "Path tracing on {} vs the CPU reference ({} threads): ms per sample (GPU = profiled \
         passes), Mrays/s (camera + bounce rays, counted by the CPU reference)\n\n\
         | scene | N | image | spp | bounces | rays/sample | megakernel ms | wavefront ms | CPU ms \
         | mega Mrays/s | wave Mrays/s | CPU Mrays/s | mega vs CPU | wave vs CPU | mean abs diff |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        info.name,
        rayon::current_num_threads()
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {}x{} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} | {:.2} | {:.2}x | {:.2}x | {:.1e} |\n",
            r.scene,
            r.resolution,
            r.width,
            r.height,
            r.spp,
            r.bounces,
            r.rays_per_sample,
            r.mega_ms_per_sample,
            r.wave_ms_per_sample,
            r.cpu_ms_per_sample,
            r.mega_mrays_s,
            r.wave_mrays_s,
            r.cpu_mrays_s,
            r.mega_over_cpu,
            r.wave_over_cpu,
            r.mega_cpu_mean_abs_diff,
        ));
    }
    print!("{md}");
    let report = PathtraceReport {
        device: info.name.clone(),
        rows,
        passes,
    };
    eprint!("{}", report.passes);
    write_outputs(&args.json, &report, &args.markdown, &md)
}
