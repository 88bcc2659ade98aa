//! `voxdag bench pathtrace`: Figure 3.9 for our scenes. Time per sample of the megakernel and
//! wavefront GPU path tracers on every DAG format, each traversing its own encoding
//! (`GpuRenderer::upload_encoded`), relative to svdag32 in the same run, and against the CPU
//! reference path tracer (rayon, all cores) in the same run; rays per second (rays = camera +
//! bounce + shadow rays, counted by the CPU reference, which traces the same paths). GPU time of
//! a sample is the sum of its profiled passes; the table reports the median over the samples.
//! With `--rounds N` every round times every format once, svdag32 first, so each round's ratios
//! are measured back to back; the table reports the medians over the rounds (a shared machine's
//! load drifts over minutes: one round's ratios are worth more than one long run per format).

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
use super::{median, scene_path, write_outputs};
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
    /// Rounds: each times every format once (svdag32 first); the table gives the median over
    /// the rounds of the ms and of each round's ratio to svdag32, with the ratios' range
    /// (3-5 on a shared machine, where one run's ratios move by 10 points).
    #[arg(long, default_value_t = 1)]
    rounds: u32,
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
    /// Every sample's GPU ms, round after round.
    mega_samples_ms: Vec<f64>,
    wave_samples_ms: Vec<f64>,
    /// Rounds timed (`--rounds`).
    rounds: u32,
    /// Relative to svdag32 in the same round (1.0 = same), the median over the rounds.
    mega_vs_svdag32: Option<f64>,
    wave_vs_svdag32: Option<f64>,
    /// Each round's ratio to svdag32.
    mega_vs_svdag32_rounds: Vec<f64>,
    wave_vs_svdag32_rounds: Vec<f64>,
    /// CPU reference ms per sample on the scene (svdag32; the median over the rounds), threads.
    cpu_ms_per_sample: Option<f64>,
    /// Each round's CPU reference ms per sample.
    cpu_rounds_ms: Vec<f64>,
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
    passes: Option<&mut String>,
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
    if let Some(passes) = passes {
        passes.push_str(&format!("{label} {mode:?}:\n{}", profiler.table()));
    }
    Ok((samples, target.read(ctx, s.spp)?))
}

/// One format's timings: per round, every sample's ms of each tracer; the first round's image.
#[derive(Default)]
struct Timing {
    mega: Vec<Vec<f64>>,
    wave: Vec<Vec<f64>>,
    image: Option<PtImage>,
}

impl Timing {
    /// Each round's median sample of one tracer (empty: not run).
    fn round_medians(rounds: &[Vec<f64>]) -> Vec<f64> {
        rounds
            .iter()
            .filter(|r| !r.is_empty())
            .map(|r| median(r))
            .collect()
    }
}

/// The CPU reference's timings: each round's ms per sample, and its rays per sample.
#[derive(Default)]
struct CpuTiming {
    rounds_ms: Vec<f64>,
    rays: u64,
}

/// Where a row's scene comes from in every round.
enum FormatSource {
    /// Uploaded from its encoding.
    Encoded(EncodedDag),
    /// The live hash DAG with this table layout, loaded from the svdag32.
    Hash(HashVariant),
}

/// One row's format: its name, encoded bytes, colour storage and scene source.
struct FormatEntry {
    label: String,
    node_bytes: Option<u64>,
    gpu_colors: &'static str,
    source: FormatSource,
}

/// What every format of one scene and resolution shares.
struct RunConfig<'a> {
    ctx: &'a std::sync::Arc<GpuContext>,
    tracer: &'a GpuPathTracer,
    settings: &'a PtSettings,
    modes: &'a [PtMode],
    scene: &'a str,
    resolution: u32,
}

impl RunConfig<'_> {
    /// Times the tracers on `scene` for one round into `timing` (the first round keeps the
    /// image and the per-pass tables).
    fn measure(
        &self,
        scene: &GpuScene,
        format: &str,
        timing: &mut Timing,
        passes: &mut String,
    ) -> Result<()> {
        let label = format!("{} N={} {format}", self.scene, self.resolution);
        let first = timing.image.is_none();
        for &mode in self.modes {
            let (samples, image) = gpu_samples(
                self.ctx,
                self.tracer,
                scene,
                self.settings,
                mode,
                &label,
                first.then_some(&mut *passes),
            )?;
            match mode {
                PtMode::Megakernel => timing.mega.push(samples),
                PtMode::Wavefront => timing.wave.push(samples),
            }
            if timing.image.is_none() {
                timing.image = Some(image);
            }
        }
        Ok(())
    }

    /// The row of `format` from its timings and svdag32's (`base`). First hits are compared on
    /// geometry (hit, t, voxel, normal): the hash DAG's colour index is a material, not the
    /// Morton rank.
    fn row(
        &self,
        format: &FormatEntry,
        timing: &Timing,
        base: &Timing,
        cpu: &CpuTiming,
    ) -> PathtraceRow {
        let s = self.settings;
        let label = format!("{} N={} {}", self.scene, self.resolution, format.label);
        let (mega_rounds, wave_rounds) = (
            Timing::round_medians(&timing.mega),
            Timing::round_medians(&timing.wave),
        );
        let ratios = |rounds: &[f64], base: &[Vec<f64>]| -> Vec<f64> {
            rounds
                .iter()
                .zip(Timing::round_medians(base))
                .map(|(a, b)| a / b)
                .collect()
        };
        let mega_ratios = ratios(&mega_rounds, &base.mega);
        let wave_ratios = ratios(&wave_rounds, &base.wave);
        let middle = |v: &[f64]| (!v.is_empty()).then(|| median(v));
        let (mega_ms, wave_ms) = (middle(&mega_rounds), middle(&wave_rounds));
        let image = timing.image.as_ref().expect("at least one tracer ran");
        let base_image = base.image.as_ref().expect("svdag32 ran first");
        let geometry = |h: &voxdag::render::FirstHit| (h.hit, h.t_bits, h.voxel, h.normal);
        let mismatches = image
            .first_hits
            .iter()
            .zip(&base_image.first_hits)
            .filter(|(x, y)| geometry(x) != geometry(y))
            .count();
        let ratio = |a: Option<f64>, b: Option<f64>| a.zip(b).map(|(a, b)| a / b);
        let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1}"));
        eprintln!(
            "{label}: megakernel {} ms, wavefront {} ms per sample, {mismatches} first-hit \
             mismatches",
            ms(mega_ms),
            ms(wave_ms)
        );
        let rays = cpu.rays;
        let mrays = |ms: Option<f64>| ms.filter(|_| rays > 0).map(|m| rays as f64 / m / 1e3);
        let cpu_ms = middle(&cpu.rounds_ms);
        PathtraceRow {
            scene: self.scene.to_string(),
            resolution: self.resolution,
            format: format.label.clone(),
            node_bytes: format.node_bytes,
            width: s.render.width,
            height: s.render.height,
            spp: s.spp,
            bounces: s.bounces,
            rays_per_sample: rays,
            mega_ms_per_sample: mega_ms,
            wave_ms_per_sample: wave_ms,
            mega_samples_ms: timing.mega.concat(),
            wave_samples_ms: timing.wave.concat(),
            rounds: timing.mega.len().max(timing.wave.len()) as u32,
            mega_vs_svdag32: middle(&mega_ratios),
            wave_vs_svdag32: middle(&wave_ratios),
            mega_vs_svdag32_rounds: mega_ratios,
            wave_vs_svdag32_rounds: wave_ratios,
            cpu_ms_per_sample: cpu_ms,
            cpu_rounds_ms: cpu.rounds_ms.clone(),
            cpu_threads: rayon::current_num_threads(),
            mega_mrays_s: mrays(mega_ms),
            wave_mrays_s: mrays(wave_ms),
            cpu_mrays_s: mrays(cpu_ms),
            mega_over_cpu: ratio(cpu_ms, mega_ms),
            wave_over_cpu: ratio(cpu_ms, wave_ms),
            first_hit_mismatches: mismatches,
            image_mean_abs_diff: mean_abs_diff(image, base_image),
            gpu_colors: format.gpu_colors.to_string(),
        }
    }
}

/// Runs the benchmark.
pub fn bench_pathtrace(args: &BenchPathtraceArgs) -> Result<()> {
    if args.spp == 0 {
        bail!("--spp must be at least 1");
    }
    if args.rounds == 0 {
        bail!("--rounds must be at least 1");
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
            let index = (!args.no_cpu).then(|| VoxelIndex::new(&dag));
            let run = RunConfig {
                ctx: &ctx,
                tracer: &tracer,
                settings: &s,
                modes: &modes,
                scene: name,
                resolution: dag.resolution,
            };
            // Encoded once; every round uploads (or loads the hash DAG) one format at a time,
            // so one format's scene is resident at a time.
            let mut formats = Vec::new();
            for format in &order {
                if format == "hash-dag" {
                    // The live hash DAG (geometry only), one row per table variant.
                    for variant in HashVariant::ALL {
                        formats.push(FormatEntry {
                            label: format!("hash-dag-{}", variant.name()),
                            node_bytes: None,
                            gpu_colors: "none",
                            source: FormatSource::Hash(variant),
                        });
                    }
                    continue;
                }
                let encoded = load_encoded(&dag, format, cached(format).as_deref())?;
                formats.push(FormatEntry {
                    label: format.clone(),
                    node_bytes: Some(encoded.byte_size()),
                    gpu_colors: color_storage,
                    source: FormatSource::Encoded(encoded),
                });
            }
            let mut timings: Vec<Timing> = formats.iter().map(|_| Timing::default()).collect();
            let mut cpu = CpuTiming::default();
            for _ in 0..args.rounds {
                // The CPU reference in every round too: its ratio is also one of a round's.
                if let Some(index) = &index {
                    let cpu_scene = CpuScene {
                        dag: &dag,
                        index,
                        colors: ColorSource::Raw(&dag.colors),
                    };
                    let start = Instant::now();
                    let traced = render_pt_cpu(&cpu_scene, &s)?;
                    cpu.rounds_ms
                        .push(start.elapsed().as_secs_f64() * 1e3 / s.spp as f64);
                    cpu.rays = traced.rays.unwrap_or(0) / s.spp as u64;
                }
                for (format, timing) in formats.iter().zip(&mut timings) {
                    match &format.source {
                        FormatSource::Hash(variant) => {
                            let hash = HashDagScene::load(&ctx, &renderer, &dag, *variant, None)?;
                            run.measure(&hash.scene, &format.label, timing, &mut passes)?;
                        }
                        FormatSource::Encoded(encoded) => {
                            let colors = chunked
                                .as_ref()
                                .map_or(ColorSource::Raw(&dag.colors), ColorSource::Chunked);
                            let scene = renderer.upload_encoded(encoded, colors)?;
                            run.measure(&scene, &format.label, timing, &mut passes)?;
                        }
                    }
                }
            }
            for (format, timing) in formats.iter().zip(&timings) {
                rows.push(run.row(format, timing, &timings[0], &cpu));
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
         (sum of the profiled passes), relative to svdag32 in the same run (with several \
         rounds: medians over the rounds, and the range of the rounds' ratios); Mrays/s (camera + \
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
    // The median ratio, and with several rounds their range.
    let vs = |v: Option<f64>, rounds: &[f64]| {
        let lo = rounds.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = rounds.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        match rounds.len() {
            0 | 1 => pct(v),
            _ => format!("{} ({}..{})", pct(v), pct(Some(lo)), pct(Some(hi))),
        }
    };
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
            vs(r.mega_vs_svdag32, &r.mega_vs_svdag32_rounds),
            f1(r.wave_ms_per_sample),
            vs(r.wave_vs_svdag32, &r.wave_vs_svdag32_rounds),
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
