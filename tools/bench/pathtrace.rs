//! `voxdag bench pathtrace`: Figure 3.9 for our scenes. Time per sample of the megakernel and
//! wavefront GPU path tracers on every DAG format, each traversing its own encoding
//! (`GpuRenderer::upload_encoded`), relative to svdag32 in the same run, and against the CPU
//! reference path tracer (rayon, all cores) in the same run; rays per second (rays = camera +
//! bounce + shadow rays, counted by the CPU reference, which traces the same paths). GPU time of
//! a sample is the sum of its profiled passes; the table reports the median over the samples.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use serde::Serialize;
use voxdag::attr::ChunkedColors;
use voxdag::dag::encode::EncodedDag;
use voxdag::dag::{Svdag, VdagFile, VoxelIndex};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::hash::HashVariant;
use voxdag::render::cpu::ColorSource;
use voxdag::render::gpu::{colors_for_allocation, GpuRenderer, GpuScene};
use voxdag::render::hash_scene::HashDagScene;
use voxdag::render::pathtrace::{render_pt_cpu, CpuScene, PtImage, PtSettings};
use voxdag::render::pathtrace_gpu::{GpuPathTracer, PtMode};
use voxdag::render::{Camera, RenderSettings};
use voxdag::scene::{self, ImportOptions};

use super::render_formats::{encode, FORMAT_NAMES};
use super::{scene_path, write_outputs};
use crate::commands::progress_bar;

/// Arguments of `voxdag bench pathtrace`.
#[derive(Args)]
pub struct BenchPathtraceArgs {
    /// Scenes: shared data set names or scene files.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "bunny,dragon,sponza-crytek"
    )]
    scenes: Vec<String>,
    /// Grid resolutions (the table: 2048,8192).
    #[arg(long, value_delimiter = ',', default_value = "2048")]
    resolutions: Vec<u32>,
    /// DAG formats, each traversed in its own encoding (svdag32 always runs first: the
    /// reference of the relative times): svdag32, ssvdag, tsvdag-sa-base, tsvdag-sa-lut,
    /// tsvdag-sa-huffman, tsvdag-sat-base, tsvdag-sat-lut, tsvdag-sat-huffman, and hash-dag (the
    /// editor's live hash DAG, geometry only: one row per table variant). The default leaves out
    /// S+A+T, whose translation search takes many minutes at 2048 (add tsvdag-sat-huffman with
    /// --cache to pay it once).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "svdag32,ssvdag,tsvdag-sa-base,tsvdag-sa-huffman,hash-dag"
    )]
    formats: Vec<String>,
    /// Image size WIDTHxHEIGHT (the table is 1920x1080; the default is a sixteenth of it).
    #[arg(long, default_value = "480x270", value_parser = crate::commands::parse_size)]
    size: (u32, u32),
    /// Samples per pixel timed per tracer and format (the median sample is reported).
    #[arg(long, default_value_t = 3)]
    spp: u32,
    /// Surface interactions per path.
    #[arg(long, default_value_t = 4)]
    bounces: u32,
    /// Tracers: megakernel, wavefront.
    #[arg(long, value_delimiter = ',', default_value = "megakernel,wavefront")]
    tracers: Vec<String>,
    /// Skip the CPU reference path tracer.
    #[arg(long)]
    no_cpu: bool,
    /// Folder keeping the voxelized and encoded scenes between runs (`SCENE-N-FORMAT.vdag`;
    /// delete it after an encoder change). Without it every run voxelizes and encodes again.
    #[arg(long)]
    cache: Option<PathBuf>,
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

/// One format of one scene at one resolution.
#[derive(Serialize)]
struct PathtraceRow {
    scene: String,
    resolution: u32,
    format: String,
    /// Bytes of the encoded nodes (None: the hash DAG, whose tables are not a file encoding).
    node_bytes: Option<u64>,
    width: u32,
    height: u32,
    spp: u32,
    bounces: u32,
    /// Rays per sample (camera + bounce + shadow), counted by the CPU reference (0 without it).
    rays_per_sample: u64,
    /// Median GPU ms per sample (None: tracer not run).
    mega_ms_per_sample: Option<f64>,
    wave_ms_per_sample: Option<f64>,
    /// Every sample's GPU ms.
    mega_samples_ms: Vec<f64>,
    wave_samples_ms: Vec<f64>,
    /// Relative to svdag32 in the same run (1.0 = same).
    mega_vs_svdag32: Option<f64>,
    wave_vs_svdag32: Option<f64>,
    /// CPU reference ms per sample on the scene (svdag32), threads.
    cpu_ms_per_sample: Option<f64>,
    cpu_threads: usize,
    mega_mrays_s: Option<f64>,
    wave_mrays_s: Option<f64>,
    cpu_mrays_s: Option<f64>,
    /// CPU time / megakernel time (target >= 0.5 on lavapipe, same cores).
    mega_over_cpu: Option<f64>,
    /// CPU time / wavefront time.
    wave_over_cpu: Option<f64>,
    /// Pixels whose first hit differs from svdag32's megakernel (must be 0).
    first_hit_mismatches: usize,
    /// Mean absolute linear pixel difference to svdag32's megakernel image (0: bit-identical
    /// paths).
    image_mean_abs_diff: f64,
    /// How the GPU read the voxel colours: `raw`, `lossless` (chunks, where the raw words
    /// exceed one GPU allocation) or `none` (no colours, or the geometry-only hash DAG).
    gpu_colors: String,
}

/// The whole run.
#[derive(Serialize)]
struct PathtraceReport {
    device: String,
    rows: Vec<PathtraceRow>,
    /// Per-pass GPU tables of the profiler, per scene, format and tracer (where the time goes).
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

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// The scene's SVDAG at `resolution` (voxelized, or loaded from the cache).
fn load_svdag(path: &Path, resolution: u32, cached: Option<&Path>) -> Result<Svdag> {
    if path.extension().is_some_and(|e| e == "vdag") {
        return Ok(Svdag::load(path)?);
    }
    if let Some(c) = cached.filter(|c| c.exists()) {
        return Svdag::load(c).with_context(|| format!("cached {}", c.display()));
    }
    let options = ImportOptions {
        resolution: Some(resolution),
        ..Default::default()
    };
    let bar = progress_bar(true);
    let dag = Svdag::from_voxels(&scene::import(path, &options, &bar)?)?;
    if let Some(c) = cached {
        dag.save(c)?;
    }
    Ok(dag)
}

/// `dag` in format `name` (encoded, or loaded from the cache).
fn load_encoded(dag: &Svdag, name: &str, cached: Option<&Path>) -> Result<EncodedDag> {
    if name == "svdag32" {
        return encode(dag, name);
    }
    if let Some(c) = cached.filter(|c| c.exists()) {
        return Ok(VdagFile::load(c)
            .with_context(|| format!("cached {}", c.display()))?
            .encoded);
    }
    let start = Instant::now();
    let encoded = encode(dag, name)?;
    eprintln!("  encoded {name} in {:.1} s", start.elapsed().as_secs_f64());
    if let Some(c) = cached {
        // Nodes only: the colours live in the svdag32 file of the cache (a copy per format
        // was 2.5 GB for sponza-crytek at 8192).
        VdagFile {
            digest: Some(encoded.digest()?),
            encoded: encoded.clone(),
            colors: Vec::new(),
            stored_colors: None,
            materials: None,
        }
        .save(c)?;
    }
    Ok(encoded)
}

/// The colours as the GPU rows upload them: `None` for raw words, or the lossless chunks the
/// renderer would make itself when the raw words exceed `max_allocation` (sponza-crytek at
/// 8192: 2.5 GB against lavapipe's 2 GiB), encoded once here for every format's upload.
fn gpu_colors(dag: &Svdag, max_allocation: u64) -> Result<Option<ChunkedColors>> {
    let start = Instant::now();
    let chunks = colors_for_allocation(&dag.colors, max_allocation)?;
    if let Some(c) = &chunks {
        eprintln!(
            "  {} raw colours ({} bytes) exceed one GPU allocation: uploaded as {} chunks \
             ({} bytes, encoded in {:.1} s)",
            dag.colors.len(),
            dag.colors.len() as u64 * 4,
            c.codec.name(),
            c.byte_size(),
            start.elapsed().as_secs_f64()
        );
    }
    Ok(chunks)
}

/// Renders `s` with `mode` after a one-sample warm-up: per-sample GPU ms and the image.
fn gpu_samples(
    ctx: &std::sync::Arc<GpuContext>,
    tracer: &GpuPathTracer,
    scene: &GpuScene,
    s: &PtSettings,
    mode: PtMode,
    label: &str,
    passes: &mut String,
) -> Result<(Vec<f64>, PtImage)> {
    let mut warm = *s;
    warm.spp = 1;
    // Warm-up: pipelines, first touch of the buffers.
    tracer.render(scene, &warm, mode, None)?;
    let mut profiler = Profiler::new(ctx)?;
    let mut samples = Vec::new();
    let target = tracer.create_target(scene, s, mode)?;
    for k in 0..s.spp {
        let mut cmd = ctx.begin_commands("bench path trace sample")?;
        tracer.record_sample(&mut cmd, scene, &target, k, Some(&mut profiler))?;
        cmd.submit()?;
        samples.push(profiler.resolve()?.iter().map(|p| p.gpu_ms).sum());
    }
    passes.push_str(&format!("{label} {mode:?}:\n{}", profiler.table()));
    Ok((samples, target.read(ctx, s.spp)?))
}

/// The svdag32 run every other format is compared with: its median ms and image.
struct Base {
    mega_ms: Option<f64>,
    wave_ms: Option<f64>,
    image: PtImage,
}

/// What every format of one scene and resolution shares.
struct RunConfig<'a> {
    ctx: &'a std::sync::Arc<GpuContext>,
    tracer: &'a GpuPathTracer,
    settings: &'a PtSettings,
    modes: &'a [PtMode],
    scene: &'a str,
    resolution: u32,
    rays: u64,
    cpu_ms: Option<f64>,
}

impl RunConfig<'_> {
    /// Times the tracers on `scene` (format `format`) and compares with `base` (set by the
    /// first call: svdag32). First hits are compared on geometry (hit, t, voxel, normal): the
    /// hash DAG's colour index is a material, not the Morton rank.
    fn row(
        &self,
        scene: &GpuScene,
        format: &str,
        node_bytes: Option<u64>,
        gpu_colors: &str,
        base: &mut Option<Base>,
        passes: &mut String,
    ) -> Result<PathtraceRow> {
        let s = self.settings;
        let label = format!("{} N={} {format}", self.scene, self.resolution);
        let mut mega = (Vec::new(), None);
        let mut wave = (Vec::new(), None);
        for &mode in self.modes {
            let (samples, image) =
                gpu_samples(self.ctx, self.tracer, scene, s, mode, &label, passes)?;
            let slot = if mode == PtMode::Megakernel {
                &mut mega
            } else {
                &mut wave
            };
            *slot = (samples, Some(image));
        }
        let mega_ms = (!mega.0.is_empty()).then(|| median(&mega.0));
        let wave_ms = (!wave.0.is_empty()).then(|| median(&wave.0));
        let image = mega.1.or(wave.1).expect("at least one tracer");
        let geometry = |h: &voxdag::render::FirstHit| (h.hit, h.t_bits, h.voxel, h.normal);
        let (mismatches, diff) = match base.as_ref() {
            None => (0, 0.0),
            Some(b) => (
                image
                    .first_hits
                    .iter()
                    .zip(&b.image.first_hits)
                    .filter(|(x, y)| geometry(x) != geometry(y))
                    .count(),
                mean_abs_diff(&image, &b.image),
            ),
        };
        let (base_mega, base_wave) = base
            .as_ref()
            .map_or((mega_ms, wave_ms), |b| (b.mega_ms, b.wave_ms));
        let ratio = |a: Option<f64>, b: Option<f64>| a.zip(b).map(|(a, b)| a / b);
        let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1}"));
        eprintln!(
            "{label}: megakernel {} ms, wavefront {} ms per sample, {mismatches} first-hit \
             mismatches",
            ms(mega_ms),
            ms(wave_ms)
        );
        let rays = self.rays;
        let mrays = |ms: Option<f64>| ms.filter(|_| rays > 0).map(|m| rays as f64 / m / 1e3);
        let row = PathtraceRow {
            scene: self.scene.to_string(),
            resolution: self.resolution,
            format: format.to_string(),
            node_bytes,
            width: s.render.width,
            height: s.render.height,
            spp: s.spp,
            bounces: s.bounces,
            rays_per_sample: rays,
            mega_ms_per_sample: mega_ms,
            wave_ms_per_sample: wave_ms,
            mega_samples_ms: mega.0,
            wave_samples_ms: wave.0,
            mega_vs_svdag32: ratio(mega_ms, base_mega),
            wave_vs_svdag32: ratio(wave_ms, base_wave),
            cpu_ms_per_sample: self.cpu_ms,
            cpu_threads: rayon::current_num_threads(),
            mega_mrays_s: mrays(mega_ms),
            wave_mrays_s: mrays(wave_ms),
            cpu_mrays_s: mrays(self.cpu_ms),
            mega_over_cpu: ratio(self.cpu_ms, mega_ms),
            wave_over_cpu: ratio(self.cpu_ms, wave_ms),
            first_hit_mismatches: mismatches,
            image_mean_abs_diff: diff,
            gpu_colors: gpu_colors.to_string(),
        };
        if base.is_none() {
            *base = Some(Base {
                mega_ms,
                wave_ms,
                image,
            });
        }
        Ok(row)
    }
}

/// Runs the benchmark.
pub fn bench_pathtrace(args: &BenchPathtraceArgs) -> Result<()> {
    if args.spp == 0 {
        bail!("--spp must be at least 1");
    }
    let mut modes = Vec::new();
    for t in &args.tracers {
        modes.push(match t.as_str() {
            "megakernel" => PtMode::Megakernel,
            "wavefront" => PtMode::Wavefront,
            _ => bail!("unknown tracer '{t}' in --tracers (known: megakernel, wavefront)"),
        });
    }
    for f in &args.formats {
        if f != "hash-dag" && !FORMAT_NAMES.contains(&f.as_str()) {
            bail!(
                "unknown format '{f}' in --formats (known: {}, hash-dag)",
                FORMAT_NAMES.join(", ")
            );
        }
    }
    let mut order = vec!["svdag32".to_string()];
    order.extend(args.formats.iter().filter(|f| *f != "svdag32").cloned());
    if let Some(c) = &args.cache {
        std::fs::create_dir_all(c).with_context(|| format!("creating {}", c.display()))?;
    }
    let ctx = GpuContext::new(&GpuOptions::default())?;
    let renderer = GpuRenderer::new(&ctx)?;
    let tracer = GpuPathTracer::new(&ctx)?;
    let mut passes = String::new();
    let mut rows = Vec::new();
    let (w, h) = args.size;
    for name in &args.scenes {
        let path = scene_path(&args.data, name)?;
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| name.clone());
        for &resolution in &args.resolutions {
            let cached = |format: &str| {
                args.cache
                    .as_ref()
                    .map(|c| c.join(format!("{stem}-{resolution}-{format}.vdag")))
            };
            let dag = load_svdag(&path, resolution, cached("svdag32").as_deref())?;
            let chunked = gpu_colors(&dag, ctx.info().max_memory_allocation_size)?;
            let color_storage = match (&chunked, dag.colors.is_empty()) {
                (Some(_), _) => "lossless",
                (None, true) => "none",
                (None, false) => "raw",
            };
            let mut s = PtSettings::new(RenderSettings::new(w, h, Camera::frame(&dag)));
            s.spp = args.spp;
            s.bounces = args.bounces;
            let (cpu_ms, rays) = if args.no_cpu {
                (None, 0)
            } else {
                let index = VoxelIndex::new(&dag);
                let cpu_scene = CpuScene {
                    dag: &dag,
                    index: &index,
                    colors: ColorSource::Raw(&dag.colors),
                };
                let start = Instant::now();
                let cpu = render_pt_cpu(&cpu_scene, &s)?;
                let ms = start.elapsed().as_secs_f64() * 1e3 / s.spp as f64;
                (Some(ms), cpu.rays.unwrap_or(0) / s.spp as u64)
            };
            let run = RunConfig {
                ctx: &ctx,
                tracer: &tracer,
                settings: &s,
                modes: &modes,
                scene: name,
                resolution: dag.resolution,
                rays,
                cpu_ms,
            };
            let mut base: Option<Base> = None;
            for format in &order {
                if format == "hash-dag" {
                    // The live hash DAG (geometry only), one row per table variant.
                    for variant in HashVariant::ALL {
                        let hash = HashDagScene::load(&ctx, &renderer, &dag, variant, None)?;
                        let label = format!("hash-dag-{}", variant.name());
                        let row =
                            run.row(&hash.scene, &label, None, "none", &mut base, &mut passes)?;
                        rows.push(row);
                    }
                    continue;
                }
                let encoded = load_encoded(&dag, format, cached(format).as_deref())?;
                let colors = chunked
                    .as_ref()
                    .map_or(ColorSource::Raw(&dag.colors), ColorSource::Chunked);
                let scene = renderer.upload_encoded(&encoded, colors)?;
                let row = run.row(
                    &scene,
                    format,
                    Some(encoded.byte_size()),
                    color_storage,
                    &mut base,
                    &mut passes,
                )?;
                rows.push(row);
            }
        }
    }
    let info = ctx.info();
    let md = markdown(&info.name, &rows);
    print!("{md}");
    let report = PathtraceReport {
        device: info.name.clone(),
        rows,
        passes,
    };
    eprint!("{}", report.passes);
    write_outputs(&args.json, &report, &args.markdown, &md)
}

/// The Markdown table of the rows.
fn markdown(device: &str, rows: &[PathtraceRow]) -> String {
    let mut md = format!(
        "Path tracing on {device} vs the CPU reference ({} threads): median GPU ms per sample \
         (sum of the profiled passes), relative to svdag32 in the same run; Mrays/s (camera + \
         bounce + shadow rays, counted by the CPU reference)\n\n\
         | scene | N | format | node bytes | image | spp | bounces | rays/sample | megakernel ms \
         | vs svdag32 | wavefront ms | vs svdag32 | CPU ms | mega Mrays/s | wave Mrays/s \
         | CPU Mrays/s | mega vs CPU | wave vs CPU | first-hit mismatches | mean abs diff |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        rayon::current_num_threads()
    );
    let f1 = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1}"));
    let f2 = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
    let pct = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:+.1}%", (v - 1.0) * 100.0));
    let x = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}x"));
    for r in rows {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {}x{} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.1e} |\n",
            r.scene,
            r.resolution,
            r.format,
            r.node_bytes.map_or("-".to_string(), |b| b.to_string()),
            r.width,
            r.height,
            r.spp,
            r.bounces,
            r.rays_per_sample,
            f1(r.mega_ms_per_sample),
            pct(r.mega_vs_svdag32),
            f1(r.wave_ms_per_sample),
            pct(r.wave_vs_svdag32),
            f1(r.cpu_ms_per_sample),
            f2(r.mega_mrays_s),
            f2(r.wave_mrays_s),
            f2(r.cpu_mrays_s),
            x(r.mega_over_cpu),
            x(r.wave_over_cpu),
            r.first_hit_mismatches,
            r.image_mean_abs_diff,
        ));
    }
    md
}
