//! `voxdag ooc ...`: out-of-core path tracing of triangle scenes (prepare, generate, render).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use voxdag::ooc::prepare::{Instance, SourceMesh};
use voxdag::ooc::{
    format, prepare, render_in_core, render_out_of_core, Eviction, GeneratedScene, OocScene,
    PrepareOptions, ProxySet, RenderOptions, SceneSource, Schedule,
};
use voxdag::scene::{self, ImportOptions};

use crate::commands::{
    check_output, parse_bytes, parse_size, parse_vec3, progress_bar, write_json,
};

/// The `ooc` subcommands.
#[derive(Subcommand)]
pub enum OocCommand {
    /// Group mesh triangles into batching points and write a scene directory with SVDAG proxies.
    Prepare(PrepareArgs),
    /// Generate a test scene directory (a landscape of mesh copies on a terrain, or a forest),
    /// streaming.
    Generate(GenerateArgs),
    /// Path-trace a scene directory out of core under a memory budget (or in core).
    Render(OocRenderArgs),
}

/// Options shared by `prepare` and `generate`.
#[derive(Args)]
pub struct LayoutArgs {
    /// Triangles per batching point (at most).
    #[arg(long, default_value_t = 100_000)]
    batch_triangles: u32,
    /// Proxy resolutions to build (comma-separated powers of two).
    #[arg(long, value_delimiter = ',', default_value = "128")]
    proxy_resolution: Vec<u32>,
    /// Output scene directory.
    #[arg(long, short)]
    output: PathBuf,
}

/// Arguments of `voxdag ooc prepare`.
#[derive(Args)]
pub struct PrepareArgs {
    /// Input meshes (.obj, .gltf, .glb).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Instance file: one copy per line, `INPUT SCALE TX TY TZ [ROTATE_Y_DEGREES]` (INPUT: 0-based
    /// index into the inputs; `#` starts a comment). Default: each input once, untransformed.
    #[arg(long)]
    instances: Option<PathBuf>,
    #[command(flatten)]
    layout: LayoutArgs,
}

/// Arguments of `voxdag ooc generate`.
#[derive(Args)]
pub struct GenerateArgs {
    /// Triangles to generate (about; the last mesh copy may overshoot).
    #[arg(long, value_parser = parse_count)]
    triangles: u64,
    #[command(flatten)]
    scene: GeneratedSceneArgs,
    #[command(flatten)]
    layout: LayoutArgs,
}

/// Which scene `ooc generate` and `bench ooc` generate, from what.
#[derive(Args)]
pub struct GeneratedSceneArgs {
    /// Scene kind.
    #[arg(long, value_enum, default_value = "landscape")]
    kind: SceneKindArg,
    /// Seed of the terrain and the placements.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Meshes to copy (default: bunny, dragon, buddha, horse and teapot of the shared data set).
    #[arg(long, value_delimiter = ',')]
    meshes: Vec<PathBuf>,
}

impl GeneratedSceneArgs {
    /// The scene's source of about `triangles` triangles (the meshes loaded).
    pub fn source(&self, triangles: u64) -> Result<SceneSource> {
        let paths = if self.meshes.is_empty() {
            default_meshes()?
        } else {
            self.meshes.clone()
        };
        let kind = match self.kind {
            SceneKindArg::Landscape => GeneratedScene::Landscape,
            SceneKindArg::Forest => GeneratedScene::Forest,
        };
        Ok(SceneSource::generate(
            kind,
            load_meshes(&paths)?,
            triangles,
            self.seed,
        )?)
    }
}

/// `--kind` of a generated scene.
#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum SceneKindArg {
    /// Terrain and scattered copies of the meshes.
    Landscape,
    /// Terrain, groves of procedural trees (vegetation) and copies of the meshes.
    Forest,
}

/// A switch (`--proxies`: queue rays only at points whose proxy they touch, or at every point
/// whose bounds they enter; `--lookahead`).
#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum OnOff {
    /// On.
    On,
    /// Off.
    Off,
}

/// The cache's eviction policy (`--eviction`).
#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum EvictionArg {
    /// The point the fewest queued rays will still visit.
    Demand,
    /// The least recently used point.
    Lru,
}

/// The renderer's choice of the next point to load (`--schedule`).
#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum ScheduleArg {
    /// The most queued rays less those still to arrive.
    Net,
    /// The most queued rays.
    Fullest,
}

/// Arguments of `voxdag ooc render`.
#[derive(Args)]
pub struct OocRenderArgs {
    /// Scene directory.
    scene: PathBuf,
    /// Bytes for cached geometry (with BVHs) plus proxies (suffixes K, M, G, T).
    #[arg(long, value_parser = parse_bytes, default_value = "1G")]
    memory_budget: u64,
    /// Proxy culling.
    #[arg(long, value_enum, default_value = "on")]
    proxies: OnOff,
    /// Proxy resolution (its proxies-R.bin must exist in the scene).
    #[arg(long, default_value_t = 128)]
    proxy_resolution: u32,
    /// Paths per pixel.
    #[arg(long, default_value_t = 4)]
    spp: u32,
    /// Seed of the random numbers.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "256x256", value_parser = parse_size)]
    size: (u32, u32),
    /// Diffuse bounces.
    #[arg(long, default_value_t = 3)]
    max_bounces: u32,
    /// Rays in flight.
    #[arg(long, default_value_t = 1 << 16)]
    rays_in_flight: usize,
    /// Lookahead: a ray waiting for a point that is not resident first visits the resident
    /// points after it; a chosen point's rays are traced again before it is loaded.
    #[arg(long, value_enum, default_value = "on")]
    lookahead: OnOff,
    /// Eviction: `demand` evicts the resident point the fewest queued rays will still visit
    /// (least recently used on ties), `lru` the least recently used one.
    #[arg(long, value_enum, default_value = "demand")]
    eviction: EvictionArg,
    /// Which queue is loaded next: `net` the most queued rays less those queued elsewhere that
    /// will still arrive, `fullest` the most queued rays.
    #[arg(long, value_enum, default_value = "net")]
    schedule: ScheduleArg,
    /// Camera position x,y,z (default: in front of and above the scene).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    eye: Option<[f32; 3]>,
    /// Point looked at x,y,z (default: the scene centre).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    target: Option<[f32; 3]>,
    /// Load everything and trace each path alone (the reference image; ignores the budget).
    #[arg(long)]
    in_core: bool,
    /// Output image: .png (sRGB) or .exr (linear RGB f32).
    #[arg(long)]
    out: PathBuf,
    /// JSON report (disk bytes, batching events, cache hits and misses, rays/s, wall time).
    #[arg(long)]
    report: Option<PathBuf>,
}

/// Parses a count with an optional k/M/G suffix (powers of 1000).
fn parse_count(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let (digits, mul) = match t.chars().last() {
        Some('k' | 'K') => (&t[..t.len() - 1], 1_000),
        Some('m' | 'M') => (&t[..t.len() - 1], 1_000_000),
        Some('g' | 'G') => (&t[..t.len() - 1], 1_000_000_000),
        _ => (t, 1),
    };
    let n: u64 = digits
        .parse()
        .map_err(|e| format!("bad count {text:?}: {e}"))?;
    n.checked_mul(mul)
        .ok_or_else(|| format!("count {text:?} too large"))
}

/// Runs an `ooc` subcommand.
pub fn run(command: OocCommand, quiet: bool) -> Result<()> {
    match command {
        OocCommand::Prepare(args) => {
            let meshes = load_meshes(&args.inputs)?;
            let instances = match &args.instances {
                Some(path) => parse_instances(path, meshes.len())?,
                None => (0..meshes.len() as u32)
                    .map(|mesh| Instance {
                        mesh,
                        transform: [
                            [1.0, 0.0, 0.0, 0.0],
                            [0.0, 1.0, 0.0, 0.0],
                            [0.0, 0.0, 1.0, 0.0],
                        ],
                    })
                    .collect(),
            };
            let source = SceneSource {
                meshes,
                instances,
                terrain: None,
            };
            write_scene(&source, &args.layout, quiet)
        }
        OocCommand::Generate(args) => {
            let source = args.scene.source(args.triangles)?;
            write_scene(&source, &args.layout, quiet)
        }
        OocCommand::Render(args) => render(&args, quiet),
    }
}

/// The shared data set's scanned meshes.
pub fn default_meshes() -> Result<Vec<PathBuf>> {
    let dir = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/data/meshes"
    ));
    let paths: Vec<PathBuf> = ["bunny", "dragon", "buddha", "horse", "teapot"]
        .iter()
        .map(|n| dir.join(format!("{n}.obj")))
        .filter(|p| p.is_file())
        .collect();
    if paths.is_empty() {
        bail!("{} has no meshes: pass --meshes", dir.display());
    }
    Ok(paths)
}

/// Loads meshes (positions and triangles only).
pub fn load_meshes(paths: &[PathBuf]) -> Result<Vec<SourceMesh>> {
    paths
        .iter()
        .map(|p| -> Result<SourceMesh> {
            let mesh = scene::load_mesh(p, &ImportOptions::default())?;
            Ok(SourceMesh::from_mesh(&mesh)?)
        })
        .collect()
}

/// Parses an instance file (see `PrepareArgs::instances`).
fn parse_instances(path: &Path, meshes: usize) -> Result<Vec<Instance>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let at = || format!("{}: line {}", path.display(), n + 1);
        let f: Vec<f64> = line
            .split_whitespace()
            .map(|v| v.parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(at)?;
        if !(5..=6).contains(&f.len()) || f.iter().any(|v| !v.is_finite()) {
            bail!("{}: expected INPUT SCALE TX TY TZ [ROTATE_Y_DEGREES]", at());
        }
        if f[0] < 0.0 || f[0].fract() != 0.0 || f[0] as usize >= meshes {
            bail!("{}: input index {} out of range (0..{meshes})", at(), f[0]);
        }
        let (s, a) = (f[1], f.get(5).copied().unwrap_or(0.0).to_radians());
        let (sn, cs) = (a.sin() * s, a.cos() * s);
        out.push(Instance {
            mesh: f[0] as u32,
            transform: [
                [cs, 0.0, sn, f[2]],
                [0.0, s, 0.0, f[3]],
                [-sn, 0.0, cs, f[4]],
            ],
        });
    }
    Ok(out)
}

fn write_scene(source: &SceneSource, layout: &LayoutArgs, quiet: bool) -> Result<()> {
    let options = PrepareOptions {
        batch_triangles: layout.batch_triangles,
        proxy_resolutions: layout.proxy_resolution.clone(),
        ..Default::default()
    };
    let start = std::time::Instant::now();
    let bar = progress_bar(quiet);
    let summary = prepare(source, &layout.output, &options, &bar)?;
    eprintln!(
        "{}: {} triangles in {} batching points, geometry {} ({:.1} s)",
        layout.output.display(),
        summary.triangles,
        summary.points,
        voxdag::safety::human_bytes(summary.geometry_bytes),
        start.elapsed().as_secs_f64()
    );
    for (r, words, bytes) in &summary.proxies {
        eprintln!(
            "  proxies {r}^3: {words} words, {}",
            voxdag::safety::human_bytes(*bytes)
        );
    }
    Ok(())
}

fn render(args: &OocRenderArgs, quiet: bool) -> Result<()> {
    check_output(&args.out)?;
    voxdag::render::pathtrace::check_extension(&args.out)?;
    if let Some(r) = &args.report {
        check_output(r)?;
    }
    let scene = OocScene::open(&args.scene)?;
    let options = RenderOptions {
        width: args.size.0,
        height: args.size.1,
        spp: args.spp,
        seed: args.seed,
        max_bounces: args.max_bounces,
        memory_budget: args.memory_budget,
        rays_in_flight: args.rays_in_flight,
        lookahead: args.lookahead == OnOff::On,
        eviction: match args.eviction {
            EvictionArg::Demand => Eviction::Demand,
            EvictionArg::Lru => Eviction::Lru,
        },
        schedule: match args.schedule {
            ScheduleArg::Net => Schedule::Net,
            ScheduleArg::Fullest => Schedule::Fullest,
        },
        eye: args.eye,
        target: args.target,
        ..Default::default()
    };
    let bar = progress_bar(quiet);
    let (image, stats) = if args.in_core {
        render_in_core(&scene, &options, &bar)?
    } else {
        let proxies = match args.proxies {
            OnOff::On => Some(ProxySet::read(
                &args.scene.join(format::proxy_file(args.proxy_resolution)),
                scene.points.len() as u32,
            )?),
            OnOff::Off => None,
        };
        render_out_of_core(&scene, proxies.as_ref(), &options, &bar)?
    };
    image.save(&args.out)?;
    eprintln!(
        "{}: {} rays in {:.2} s ({:.2} Mrays/s), read {}, {} batching events, cache {} hits / {} misses",
        args.out.display(),
        stats.rays,
        stats.wall_s,
        stats.rays_per_s / 1e6,
        voxdag::safety::human_bytes(stats.disk_bytes_read),
        stats.batching_events,
        stats.cache_hits,
        stats.cache_misses
    );
    if let Some(r) = &args.report {
        write_json(r, &stats)?;
    }
    Ok(())
}
