//! The subcommands of the `voxdag` CLI (everything but the benchmarks).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use voxdag::atomic_file::write_atomic;
use voxdag::dag::{export_vox, export_xyz_u32_file, DagStats, Svdag, VoxelIndex};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{render_cpu, Camera, RenderSettings};
use voxdag::scene::{self, ImportOptions};

use crate::{BuildArgs, DemoArgs, ExportArgs, ExportFormat, RenderArgs, StatsArgs};

/// What `voxdag build --report` writes: the inputs, the outcome and the cost of one build.
#[derive(Serialize, Deserialize)]
pub struct BuildReport {
    /// Input scene path.
    pub input: PathBuf,
    /// Grid resolution.
    pub resolution: u32,
    /// Occupied voxels.
    pub voxels: u64,
    /// Seconds spent importing and voxelizing.
    pub voxelize_s: f64,
    /// Seconds spent building the SVDAG.
    pub build_s: f64,
    /// Peak resident memory of the process in bytes (VmHWM).
    pub peak_rss_bytes: u64,
    /// Node counts and bytes of the result.
    pub stats: DagStats,
}

/// A progress bar with voxdag's style, hidden when `quiet`.
pub fn progress_bar(quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg:>12} [{elapsed_precise}] {wide_bar} {pos}/{len} ({eta})",
        )
        .expect("valid progress template"),
    );
    bar
}

/// Peak resident set size of this process in bytes, from /proc/self/status (0 if unavailable).
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
            let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
            Some(kib * 1024)
        })
        .unwrap_or(0)
}

/// Parses "WIDTHxHEIGHT".
pub fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT, e.g. 1024x768")?;
    let parse = |s: &str| {
        s.trim()
            .parse::<u32>()
            .map_err(|e| format!("bad size {s:?}: {e}"))
    };
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!(
            "image size {w}x{h} out of range (1..=16384 per side)"
        ));
    }
    Ok((w, h))
}

/// Parses "x,y,z".
pub fn parse_vec3(text: &str) -> Result<[f32; 3], String> {
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("expected x,y,z, got {text:?}"));
    }
    let mut v = [0f32; 3];
    for (out, part) in v.iter_mut().zip(parts) {
        *out = part
            .trim()
            .parse()
            .map_err(|e| format!("bad number {part:?}: {e}"))?;
        if !out.is_finite() {
            return Err(format!("{part:?} is not a finite number"));
        }
    }
    Ok(v)
}

/// Imports, voxelizes and builds the SVDAG of a scene; returns the DAG and the build report.
pub fn build_scene(args: &BuildArgs, quiet: bool) -> Result<(Svdag, BuildReport)> {
    let options = ImportOptions {
        resolution: args.resolution,
        vox_scale: args.vox_scale,
        texture_override: args.texture.clone(),
    };
    let bar = progress_bar(quiet);
    let start = Instant::now();
    let mut voxels = scene::import(&args.input, &options, &bar)?;
    bar.finish_and_clear();
    if args.no_colors {
        voxels.colors = Vec::new();
    }
    let voxelize_time = start.elapsed();
    let start = Instant::now();
    let dag = Svdag::from_voxels(&voxels)?;
    let build_time = start.elapsed();
    drop(voxels);
    let stats = dag.stats();
    let report = BuildReport {
        input: args.input.clone(),
        resolution: dag.resolution,
        voxels: stats.voxels,
        voxelize_s: voxelize_time.as_secs_f64(),
        build_s: build_time.as_secs_f64(),
        peak_rss_bytes: peak_rss_bytes(),
        stats,
    };
    Ok((dag, report))
}

/// `voxdag build`.
pub fn build(args: &BuildArgs, quiet: bool) -> Result<()> {
    check_output_dir(&args.output)?;
    if let Some(report) = &args.report {
        check_output_dir(report)?;
    }
    let (dag, report) = build_scene(args, quiet)?;
    dag.save(&args.output)?;
    println!(
        "{}: {}^3, {} voxels, {} SVDAG nodes, {} bytes (voxelize {:.2} s, build {:.2} s, peak {:.0} MiB)",
        args.output.display(),
        report.resolution,
        report.voxels,
        report.stats.levels.iter().map(|l| l.svdag).sum::<u64>(),
        report.stats.bytes.svdag32,
        report.voxelize_s,
        report.build_s,
        report.peak_rss_bytes as f64 / (1024.0 * 1024.0)
    );
    if let Some(path) = &args.report {
        write_json(path, &report)?;
    }
    Ok(())
}

/// `voxdag stats`.
pub fn stats(args: &StatsArgs) -> Result<()> {
    let dag = Svdag::load(&args.file)?;
    let stats = dag.stats_with_symmetry();
    if args.json {
        println!("{}", serde_json::to_string(&stats)?);
    } else {
        print!("{}", stats_table(&args.file, &stats));
    }
    Ok(())
}

/// A human-readable table of DAG statistics (with the transform columns when computed).
pub fn stats_table(file: &Path, stats: &DagStats) -> String {
    let symmetry = stats.levels.iter().any(|l| l.sa.is_some());
    let mut out = format!(
        "{}\n  resolution  {}^3\n  voxels      {}\n  bytes       svo {}  svdag32 {}\n  level  node size        svo      svdag",
        file.display(),
        stats.resolution,
        stats.voxels,
        stats.bytes.svo,
        stats.bytes.svdag32
    );
    if symmetry {
        out += "     ssvdag          s          a         sa";
    }
    out += "\n";
    let cell = |v: Option<u64>| v.map_or_else(|| "-".to_string(), |v| v.to_string());
    for level in &stats.levels {
        let size = 4u64 << level.level;
        out += &format!(
            "  {:>5}  {:>9} {:>10} {:>10}",
            level.level,
            format!("{size}^3"),
            level.svo,
            level.svdag
        );
        if symmetry {
            out += &format!(
                " {:>10} {:>10} {:>10} {:>10}",
                cell(level.ssvdag),
                cell(level.s),
                cell(level.a),
                cell(level.sa)
            );
        }
        out += "\n";
    }
    out
}

/// `voxdag export-voxels`.
pub fn export_voxels(args: &ExportArgs) -> Result<()> {
    let dag = Svdag::load(&args.file)?;
    check_output_dir(&args.output)?;
    match args.format {
        ExportFormat::XyzU32 => export_xyz_u32_file(&dag, &args.output)?,
        ExportFormat::Vox => export_vox(&dag, &args.output)?,
    }
    println!(
        "{}: wrote {} voxels",
        args.output.display(),
        dag.voxel_count()
    );
    Ok(())
}

/// Builds render settings from the CLI camera flags.
fn render_settings(args: &RenderArgs, dag: &Svdag) -> RenderSettings {
    let mut camera = Camera::frame(dag);
    if let Some(eye) = args.eye {
        camera.eye = eye;
    }
    if let Some(target) = args.target {
        camera.target = target;
    }
    if let Some(fov) = args.fov {
        camera.fov_y_deg = fov;
    }
    let mut settings = RenderSettings::new(args.size.0, args.size.1, camera);
    settings.shadows = !args.no_shadows;
    settings
}

/// `voxdag render`.
pub fn render(args: &RenderArgs) -> Result<()> {
    if let Some(fov) = args.fov {
        if !(1.0..=179.0).contains(&fov) {
            bail!("--fov {fov} out of range (1..=179 degrees)");
        }
    }
    check_output_dir(&args.out)?;
    if let Some(trace) = &args.trace {
        check_output_dir(trace)?;
    }
    let dag = Svdag::load(&args.file)?;
    let settings = render_settings(args, &dag);
    let start = Instant::now();
    let image = if args.cpu {
        let index = VoxelIndex::new(&dag);
        render_cpu(&dag, &index, &settings)?
    } else {
        let context = GpuContext::new(&GpuOptions::default())?;
        let image = render_gpu(
            &context,
            &dag,
            &settings,
            args.profile,
            args.trace.as_deref(),
        )?;
        drop(context);
        image
    };
    image.save_png(&args.out)?;
    println!(
        "{}: {}x{} in {}",
        args.out.display(),
        args.size.0,
        args.size.1,
        seconds(start.elapsed())
    );
    Ok(())
}

/// Renders on the GPU, printing the profile table and writing the trace when asked.
fn render_gpu(
    context: &Arc<GpuContext>,
    dag: &Svdag,
    settings: &RenderSettings,
    print_profile: bool,
    trace: Option<&Path>,
) -> Result<voxdag::render::RenderOutput> {
    let renderer = GpuRenderer::new(context)?;
    let mut profiler = Profiler::new(context)?;
    let scene = profiler.cpu_span("upload", || renderer.upload(dag))?;
    let image = renderer.render(&scene, settings, Some(&mut profiler))?;
    if print_profile {
        print!("{}", profiler.table());
    }
    if let Some(path) = trace {
        profiler.write_chrome_trace(path)?;
        println!(
            "{}: Chrome trace written (open in Perfetto)",
            path.display()
        );
    }
    Ok(image)
}

/// `voxdag demo`: the README's quick start.
pub fn demo(args: &DemoArgs, quiet: bool) -> Result<()> {
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/avocado/Avocado.gltf");
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("creating {}", args.out_dir.display()))?;
    let vdag = args.out_dir.join("avocado.vdag");
    let build_args = BuildArgs {
        input,
        resolution: Some(args.resolution),
        vox_scale: 1,
        texture: None,
        no_colors: false,
        output: vdag.clone(),
        report: Some(args.out_dir.join("avocado-build.json")),
    };
    build(&build_args, quiet)?;
    let render_args = RenderArgs {
        file: vdag.clone(),
        size: (1024, 768),
        out: args.out_dir.join("avocado.png"),
        eye: None,
        target: None,
        fov: None,
        no_shadows: false,
        cpu: false,
        profile: true,
        trace: Some(args.out_dir.join("avocado-trace.json")),
    };
    render(&render_args)?;
    let stats_args = StatsArgs {
        file: vdag.clone(),
        json: false,
    };
    stats(&stats_args)?;
    write_json(
        &args.out_dir.join("avocado-stats.json"),
        &Svdag::load(&vdag)?.stats(),
    )?;
    Ok(())
}

/// Fails early, before any work, when the output's folder does not exist.
fn check_output_dir(output: &Path) -> Result<()> {
    let dir = output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if !dir.is_dir() {
        bail!("output folder {} does not exist", dir.display());
    }
    Ok(())
}

/// Writes pretty JSON atomically.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    write_atomic(path, |w| Ok(serde_json::to_writer_pretty(w, value)?))
        .with_context(|| format!("writing {}", path.display()))
}

/// "1.23 s" or "45.6 ms".
pub fn seconds(d: Duration) -> String {
    if d.as_secs_f64() >= 1.0 {
        format!("{:.2} s", d.as_secs_f64())
    } else {
        format!("{:.1} ms", d.as_secs_f64() * 1e3)
    }
}
