//! `voxdag render --pt`: the path tracers (GPU megakernel or wavefront, CPU reference).

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use clap::Args;
use voxdag::dag::encode::EncodedDag;
use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::render::cpu::ColorSource;
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::pathtrace::{
    check_extension, render_pt_cpu, CpuScene, PtImage, PtSettings, Sun, DEFAULT_BOUNCES,
    DEFAULT_RR_DEPTH,
};
use voxdag::render::pathtrace_gpu::{GpuPathTracer, PtMode};
use voxdag::render::RenderSettings;

/// The path-tracing flags of `voxdag render` (docs/pathtracing.md).
#[derive(Args, Clone, Debug, Default)]
pub struct PtArgs {
    /// Path trace (Lambertian voxels, constant environment, optional sun) instead of the raster
    /// shading; --out may then end in .png (tonemapped) or .exr (linear HDR).
    #[arg(long)]
    pub pt: bool,
    /// Samples per pixel (default 16).
    #[arg(long, requires = "pt")]
    pub spp: Option<u32>,
    /// Diffuse surface interactions a path may have before it must escape (default 4;
    /// Mitsuba's max_depth = BOUNCES + 1).
    #[arg(long, requires = "pt")]
    pub bounces: Option<u32>,
    /// Constant environment radiance "r,g,b" (default 1,1,1).
    #[arg(long, requires = "pt", value_parser = parse_floats::<3>, allow_hyphen_values = true)]
    pub env: Option<[f32; 3]>,
    /// A sun (directional light, next-event estimation) "x,y,z,intensity": direction towards it.
    #[arg(long, requires = "pt", value_parser = parse_floats::<4>, allow_hyphen_values = true)]
    pub sun: Option<[f32; 4]>,
    /// Uniform albedo in [0, 1] instead of the voxel colours.
    #[arg(long, requires = "pt", allow_hyphen_values = true)]
    pub albedo: Option<f32>,
    /// First surface interaction that plays Russian roulette (default 3; more than --bounces:
    /// never). A path survives interaction i >= RR_DEPTH with p = min(max throughput, 0.95).
    #[arg(long, requires = "pt")]
    pub rr_depth: Option<u32>,
    /// Seed of the counter-based RNG (default 0).
    #[arg(long, requires = "pt")]
    pub seed: Option<u32>,
    /// Use the wavefront path tracer instead of the megakernel.
    #[arg(long, requires = "pt", conflicts_with = "cpu")]
    pub wavefront: bool,
}

/// `N` comma-separated numbers. Non-finite and negative values pass here: the path tracer's
/// own validation rejects them with a one-line error naming the flag.
pub fn parse_floats<const N: usize>(text: &str) -> Result<[f32; N], String> {
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} comma-separated numbers, got {text:?}"
        ));
    }
    let mut v = [0f32; N];
    for (out, part) in v.iter_mut().zip(parts) {
        *out = part
            .trim()
            .parse()
            .map_err(|e| format!("bad number {part:?}: {e}"))?;
    }
    Ok(v)
}

impl PtArgs {
    /// The path tracer's settings for `render` (validated: bad values are one-line errors).
    pub fn settings(&self, render: RenderSettings) -> Result<PtSettings> {
        let mut s = PtSettings::new(render);
        s.spp = self.spp.unwrap_or(16);
        s.bounces = self.bounces.unwrap_or(DEFAULT_BOUNCES);
        if let Some(env) = self.env {
            s.env = env;
        }
        s.sun = self.sun.map(|v| Sun {
            dir: [v[0], v[1], v[2]],
            intensity: v[3],
        });
        s.albedo = self.albedo;
        s.seed = self.seed.unwrap_or(0);
        s.rr_depth = self.rr_depth.unwrap_or(DEFAULT_RR_DEPTH);
        s.validate()?;
        Ok(s)
    }
}

/// Checks the flags and the output's extension before the scene is loaded.
pub fn check(args: &PtArgs, out: &Path) -> Result<()> {
    check_extension(out)?;
    // Any image size: only the values are checked here.
    args.settings(RenderSettings::new(
        1,
        1,
        voxdag::render::Camera::orbit_default(8),
    ))?;
    Ok(())
}

/// The CPU reference path tracer on `dag`; writes `out`.
pub fn render_cpu(
    args: &PtArgs,
    dag: &Svdag,
    colors: ColorSource,
    render: RenderSettings,
    out: &Path,
) -> Result<()> {
    let settings = args.settings(render)?;
    let start = Instant::now();
    let index = VoxelIndex::new(dag);
    let scene = CpuScene {
        dag,
        index: &index,
        colors,
    };
    let image = render_pt_cpu(&scene, &settings)?;
    finish(&image, &settings, start, out)
}

/// The GPU path tracer (megakernel, or wavefront with `--wavefront`) on `dag` in its own
/// encoding; writes `out`, prints the profile and writes the trace when asked.
pub fn render_gpu(
    args: &PtArgs,
    dag: &EncodedDag,
    colors: ColorSource,
    render: RenderSettings,
    print_profile: bool,
    trace: Option<&Path>,
    out: &Path,
) -> Result<()> {
    let settings = args.settings(render)?;
    let start = Instant::now();
    let mode = if args.wavefront {
        PtMode::Wavefront
    } else {
        PtMode::Megakernel
    };
    let context = GpuContext::new(&GpuOptions::default())?;
    let renderer = GpuRenderer::new(&context)?;
    let tracer = GpuPathTracer::new(&context)?;
    let mut profiler = Profiler::new(&context)?;
    let scene = profiler.cpu_span("upload", || renderer.upload_encoded(dag, colors))?;
    let profiled = print_profile || trace.is_some();
    let image = tracer.render(&scene, &settings, mode, profiled.then_some(&mut profiler))?;
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
    finish(&image, &settings, start, out)
}

/// Writes `image` to `out` and prints what was rendered and how long it took.
fn finish(image: &PtImage, settings: &PtSettings, start: Instant, out: &Path) -> Result<()> {
    image.save(out)?;
    println!(
        "{}: {}x{}, {} spp, {} bounces in {}",
        out.display(),
        settings.render.width,
        settings.render.height,
        settings.spp,
        settings.bounces,
        crate::commands::seconds(start.elapsed())
    );
    Ok(())
}
