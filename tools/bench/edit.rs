//! `voxdag bench edit`: the dissertation's Figure 4.8 for our scenes — per-kernel GPU times of
//! the edit pipeline, whole-edit wall time, temporary SVO bytes and DAG bytes before / after, for
//! each table layout, and the CPU reference editor (all cores) on the same generated replays in
//! the same run, with the GPU / CPU ratio per replay. Plus the bytes target: after N random
//! edits and GC, the hash DAG's item bytes against a from-scratch build of the kept roots.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use serde::Serialize;
use voxdag::attr::materials::Materials;
use voxdag::dag::Svdag;
use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::gpu::{GpuDagError, GpuHashDag, GpuHashDagConfig};
use voxdag::edit::tool::{CopyParams, Shape, Tool};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::scene::{self, morton, ImportOptions};

use super::{median, scene_path, write_outputs};
use crate::commands::quantize_materials;
use crate::edit::{tool_name, TableArg, TeamArg};

/// Arguments of `voxdag bench edit`.
#[derive(Args)]
pub struct BenchEditArgs {
    /// Scenes: names in the shared data set (bunny, sponza-crytek, ...) or scene files.
    #[arg(long, value_delimiter = ',', default_value = "bunny,sponza-crytek")]
    scenes: Vec<String>,
    /// Grid resolution (the dissertation's is 8192; tool radii scale with it).
    #[arg(long, default_value_t = 1024)]
    resolution: u32,
    /// GPU table layouts.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "atomic64,ticket_board,accel32,accel8"
    )]
    tables: Vec<TableArg>,
    /// Lanes per item in the table passes, each a row per table layout (the default single
    /// lanes; `subgroup,single-lane` compares both in one run).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "single-lane")]
    teams: Vec<TeamArg>,
    /// Edits of the long sphere replay (radius 128..512 at 8192, scaled with the resolution,
    /// at spread surface points, added and removed in turn): the rate once every pipeline is
    /// made, which the short replays' first edits hide; 0 skips it.
    #[arg(long, default_value_t = 200)]
    long_replay: usize,
    /// Materials: the scenes' colours quantized into a palette of at most this many (1..=16,
    /// as `build --materials`), so leaves carry 4-bit ids and the paint replay changes them;
    /// 0: geometry only (no paint replay). The bytes target stays geometry only.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=16))]
    materials: u32,
    /// Random edits of the bytes target (first scene, first table layout); 0 skips it.
    #[arg(long, default_value_t = 1000)]
    random_edits: usize,
    /// Undo depth of the bytes target (its kept history).
    #[arg(long, default_value_t = 8)]
    random_undo_depth: usize,
    /// Folder of the shared data set.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data"))]
    data: PathBuf,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-edit.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-edit.md")]
    markdown: PathBuf,
}

impl BenchEditArgs {
    pub(super) fn outputs(&self) -> Vec<&std::path::Path> {
        vec![self.json.as_path(), self.markdown.as_path()]
    }
}

/// Kernel groups of Figure 4.8, in column order.
const GROUPS: [&str; 6] = [
    "traversal+SVO",
    "SVO dedup",
    "merge search",
    "merge insert",
    "parent update",
    "rest",
];

/// The Figure 4.8 group of a profiled pass.
fn group_of(pass: &str) -> &'static str {
    match pass {
        "edit traverse" | "edit traverse small levels" | "edit leaves" => GROUPS[0],
        p if p.starts_with("dedup") => GROUPS[1],
        // Single lanes: the search also claims (the SVO dedup folded into search and insert);
        // a small level's search, claim and insert share one dispatch, and the small top
        // levels' whole merge another (build, search, insert, resolve): counted as the search.
        "hash search"
        | "hash search and claim"
        | "hash search, claim and insert"
        | "edit merge small levels" => GROUPS[2],
        "hash insert" | "edit mark" => GROUPS[3],
        "edit build items" | "edit resolve" => GROUPS[4],
        _ => GROUPS[5],
    }
}

/// One engine on one replay.
#[derive(Serialize)]
struct ReplayRow {
    scene: String,
    resolution: u32,
    replay: String,
    /// `cpu` or the GPU table layout.
    engine: String,
    edits: usize,
    /// `ok`, or `n/a: <why>` (a tool not on the GPU yet).
    status: String,
    /// Whole-edit wall time, summed and largest, timed without the profiler.
    edit_ms_total: f64,
    edit_ms_max: f64,
    /// The median edit's wall time: what an edit costs once the first edits' one-time work
    /// (the CPU tables' first growth, first touches of fresh memory) is out of the picture.
    edit_ms_median: f64,
    /// GPU: making the edit pipelines of the replay's tools, before the timed edits (lavapipe
    /// compiles one in ~10-30 ms; each would otherwise be made by the first edit with its tool).
    #[serde(skip_serializing_if = "Option::is_none")]
    pipelines_ms: Option<f64>,
    /// The same replay's wall time with every pass profiled (the run that gives `kernels_ms`):
    /// on lavapipe the timestamps around ~100 passes per edit cost about an edit; None for the
    /// CPU.
    profiled_ms_total: Option<f64>,
    /// GPU ms per kernel group (Figure 4.8), summed over the replay.
    kernels_ms: BTreeMap<&'static str, f64>,
    /// Temporary SVO bytes (inner nodes 32 B, leaves 8 B), largest edit of the replay.
    temp_svo_bytes_max: u64,
    /// Item bytes reachable from the live roots before the replay and after it (after GC).
    dag_bytes_before: u64,
    dag_bytes_after: u64,
    /// This engine's total edit time over the CPU reference's on the same replay.
    vs_cpu: Option<f64>,
    /// This engine's median edit time over the CPU reference's.
    median_vs_cpu: Option<f64>,
    /// GPU runs, per edit on average: queue submissions, host waits and profiled passes
    /// (dispatches), from `GpuContext::stats` and the profiler; None for the CPU.
    per_edit: Option<[f64; 3]>,
}

/// The bytes target.
#[derive(Serialize)]
struct BytesRow {
    scene: String,
    resolution: u32,
    table: String,
    edits: usize,
    undo_depth: usize,
    kept_roots: usize,
    gc_freed_items: u64,
    /// Item bytes of the hash DAG after GC.
    dag_bytes: u64,
    /// Item bytes of a fresh hash DAG holding the same kept roots, built from scratch.
    from_scratch_bytes: u64,
    ratio: f64,
    edit_s: f64,
}

#[derive(Serialize)]
struct Report {
    resolution: u32,
    /// Palette size of the edited scenes (0: geometry only).
    materials: u32,
    cpu_threads: usize,
    device: String,
    replays: Vec<ReplayRow>,
    bytes: Option<BytesRow>,
}

/// A generated replay.
struct Replay {
    name: &'static str,
    tools: Vec<Tool>,
}

/// `count` occupied voxels spread over the scene (evenly through the Morton order).
fn surface_points(codes: &[u64], count: usize) -> Vec<[f32; 3]> {
    (0..count)
        .map(|i| {
            let c = codes[(i * 7919 + i * codes.len() / count) % codes.len()];
            morton::decode(c).map(|v| v as f32 + 0.5)
        })
        .collect()
}

/// The dabs of a paint stroke dragged over the surface: every `step`-th voxel in Morton order
/// from a third into the scene. Each dab is centred on a voxel of the surface and Morton order
/// keeps most of the next dabs a few voxels on, so every dab paints voxels (a straight line
/// between two surface points crosses empty space: session 50).
fn stroke_points(codes: &[u64], count: usize, step: usize) -> Vec<[f32; 3]> {
    let start = codes.len() / 3;
    (0..count)
        .map(|k| {
            let c = codes[(start + k * step) % codes.len()];
            morton::decode(c).map(|v| v as f32 + 0.5)
        })
        .collect()
}

/// A sphere of material 0 added (`add`) or removed.
fn sphere(center: [f32; 3], radius: f32, add: bool) -> Tool {
    if add {
        Tool::Add {
            shape: Shape::Sphere,
            center,
            radius,
            material: 0,
        }
    } else {
        Tool::Remove {
            shape: Shape::Sphere,
            center,
            radius,
        }
    }
}

/// The replays: spheres (radius 64..1024 at 8192, scaled) added and removed, a copy stroke,
/// paint strokes in a material scene (materials 1.. of its `palette`-entry palette in turn;
/// `None`: geometry only, where paint changes nothing), and `long` spheres (radius 128..512 at
/// 8192) added and removed in turn.
fn replays(codes: &[u64], resolution: u32, long: usize, palette: Option<u32>) -> Vec<Replay> {
    let scale = resolution as f32 / 8192.0;
    let p = surface_points(codes, 64);
    let mut spheres = Vec::new();
    for (i, r) in [64.0f32, 128.0, 256.0, 512.0, 1024.0].iter().enumerate() {
        let radius = (r * scale).max(2.0);
        spheres.push(sphere(p[2 * i], radius, true));
        spheres.push(sphere(p[2 * i + 1], radius, false));
    }
    let r = (64.0 * scale).max(4.0);
    let copy = (0..8)
        .map(|k| {
            let t = k as f32 * r;
            Tool::Copy(CopyParams {
                source: p[20],
                dest: [p[21][0] + t, p[21][1], p[21][2]],
                center: p[20],
                radius: r,
                transform: None,
            })
        })
        .collect();
    let long_spheres = surface_points(codes, long)
        .into_iter()
        .enumerate()
        .map(|(i, center)| {
            let radius = ((128 + (i * 37) % 385) as f32 * scale).max(2.0);
            sphere(center, radius, i % 2 == 0)
        })
        .collect::<Vec<_>>();
    let mut out = vec![
        Replay {
            name: "spheres",
            tools: spheres,
        },
        Replay {
            name: "copy",
            tools: copy,
        },
    ];
    if let Some(palette) = palette {
        let radius = (32.0 * scale).max(2.0);
        // Dabs about half a radius apart: a patch of surface that wide holds ~(r / 2)^2 voxels.
        let step = ((radius / 2.0) as usize).pow(2).max(1);
        let paint = stroke_points(codes, 16, step)
            .into_iter()
            .enumerate()
            .map(|(k, center)| Tool::Paint {
                center,
                radius,
                // Every material in turn: each dab repaints what the one before it painted
                // (with one material to paint, a stroke over voxels of it changes nothing).
                material: (k as u32 % palette) as u8,
            })
            .collect();
        out.push(Replay {
            name: "paint",
            tools: paint,
        });
    }
    if !long_spheres.is_empty() {
        out.push(Replay {
            name: "long spheres",
            tools: long_spheres,
        });
    }
    out
}

/// Item bytes per table of GC statistics.
fn live_bytes(per_table: &[u64]) -> u64 {
    per_table
        .iter()
        .enumerate()
        .map(|(t, &n)| n * 4 * (t as u64 + 2))
        .sum()
}

fn run_cpu(
    scene: &str,
    svdag: &Svdag,
    materials: Option<&Materials>,
    replay: &Replay,
) -> Result<ReplayRow> {
    let mut dag = HashDag::new(svdag.resolution, materials.is_some())?;
    let root = dag.insert_svdag(svdag, materials.map(|m| m.ids.as_slice()))?;
    let before = dag.item_bytes();
    let mut editor = CpuEditor::new(dag, root, 64);
    let mut times = Vec::new();
    for tool in &replay.tools {
        let start = Instant::now();
        editor.edit(tool)?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
    }
    editor.gc()?;
    Ok(ReplayRow {
        scene: scene.into(),
        resolution: svdag.resolution,
        replay: replay.name.into(),
        engine: "cpu".into(),
        edits: times.len(),
        status: "ok".into(),
        edit_ms_total: times.iter().sum(),
        edit_ms_max: times.iter().cloned().fold(0.0, f64::max),
        edit_ms_median: median(&times),
        pipelines_ms: None,
        profiled_ms_total: None,
        kernels_ms: BTreeMap::new(),
        temp_svo_bytes_max: 0,
        dag_bytes_before: before,
        dag_bytes_after: editor.dag().item_bytes(),
        vs_cpu: Some(1.0),
        median_vs_cpu: Some(1.0),
        per_edit: None,
    })
}

/// `replay` on a fresh GPU hash DAG of `svdag` with `table` tables, twice: timed without the
/// profiler, then on another fresh load with it for the kernel groups and pass counts.
fn run_gpu(
    ctx: &Arc<GpuContext>,
    scene: &str,
    svdag: &Svdag,
    materials: Option<&Materials>,
    engine: GpuEngine,
    replay: &Replay,
) -> Result<ReplayRow> {
    let mut row = replay_gpu(ctx, scene, svdag, materials, engine, replay, None)?;
    if row.status != "ok" {
        return Ok(row);
    }
    let mut profiler = Profiler::new(ctx)?;
    let profiled = replay_gpu(
        ctx,
        scene,
        svdag,
        materials,
        engine,
        replay,
        Some(&mut profiler),
    )?;
    row.profiled_ms_total = Some(profiled.edit_ms_total);
    row.kernels_ms = profiled.kernels_ms;
    if let (Some(per_edit), Some(p)) = (&mut row.per_edit, profiled.per_edit) {
        per_edit[2] = p[2];
    }
    Ok(row)
}

/// A GPU row's configuration: the table layout and the lanes per item.
#[derive(Clone, Copy)]
struct GpuEngine {
    table: TableArg,
    team: TeamArg,
}

impl GpuEngine {
    /// The row's engine column: the layout, and subgroup teams where they replace the
    /// default single lanes.
    fn name(self) -> String {
        match self.team {
            TeamArg::SingleLane => self.table.variant().name().into(),
            TeamArg::Subgroup => format!("{} subgroup", self.table.variant().name()),
        }
    }
}

/// One run of `replay` on a fresh GPU hash DAG, profiled when `profiler` is given (else the
/// kernel groups stay 0 and the pass count is 0).
fn replay_gpu(
    ctx: &Arc<GpuContext>,
    scene: &str,
    svdag: &Svdag,
    materials: Option<&Materials>,
    engine: GpuEngine,
    replay: &Replay,
    mut profiler: Option<&mut Profiler>,
) -> Result<ReplayRow> {
    let config = GpuHashDagConfig {
        team: engine.team.mode(),
        ..GpuHashDagConfig::sized_by_load(engine.table.variant())
    };
    let mut hd = match materials {
        Some(m) => GpuHashDag::load_materials(ctx, &config, svdag, m, None)?,
        None => GpuHashDag::load(ctx, &config, svdag, None)?,
    };
    let before = live_bytes(&hd.gc(None)?.live_per_table);
    let pipelines_ms = hd.prepare_tools(&replay.tools)?;
    let mut row = ReplayRow {
        scene: scene.into(),
        resolution: svdag.resolution,
        replay: replay.name.into(),
        engine: engine.name(),
        edits: 0,
        status: "ok".into(),
        edit_ms_total: 0.0,
        edit_ms_max: 0.0,
        edit_ms_median: 0.0,
        pipelines_ms: Some(pipelines_ms),
        profiled_ms_total: None,
        kernels_ms: GROUPS.iter().map(|g| (*g, 0.0)).collect(),
        temp_svo_bytes_max: 0,
        dag_bytes_before: before,
        dag_bytes_after: 0,
        vs_cpu: None,
        median_vs_cpu: None,
        per_edit: None,
    };
    let stats = ctx.stats();
    let mut times = Vec::with_capacity(replay.tools.len());
    let mut passes = 0;
    for tool in &replay.tools {
        let from = profiler.as_ref().map_or(0, |p| p.passes().len());
        let start = Instant::now();
        let report = match hd.edit(tool, profiler.as_deref_mut()) {
            Ok(r) => r,
            Err(GpuDagError::Invalid(why)) if why.contains("not on the GPU") => {
                row.status = format!("n/a: {} not on the GPU yet", tool_name(tool));
                return Ok(row);
            }
            Err(e) => return Err(e.into()),
        };
        let ms = start.elapsed().as_secs_f64() * 1e3;
        row.edits += 1;
        row.edit_ms_total += ms;
        row.edit_ms_max = row.edit_ms_max.max(ms);
        times.push(ms);
        if let Some(profiler) = profiler.as_deref() {
            for p in &profiler.passes()[from..] {
                *row.kernels_ms.entry(group_of(&p.name)).or_insert(0.0) += p.gpu_ms;
            }
            passes += profiler.passes().len() - from;
        }
        let temp: u64 = report
            .temporary_nodes
            .iter()
            .enumerate()
            .map(|(l, &n)| n as u64 * if l == 0 { 8 } else { 32 })
            .sum();
        row.temp_svo_bytes_max = row.temp_svo_bytes_max.max(temp);
    }
    row.edit_ms_median = median(&times);
    let stats = ctx.stats().since(stats);
    let edits = row.edits.max(1) as f64;
    row.per_edit = Some([
        stats.submissions as f64 / edits,
        stats.host_waits as f64 / edits,
        passes as f64 / edits,
    ]);
    row.dag_bytes_after = live_bytes(&hd.gc(None)?.live_per_table);
    Ok(row)
}

/// N random sphere / cube adds and removes near the surface, GC, then the hash DAG's item bytes
/// against a fresh hash DAG built from the kept roots' voxels.
fn bytes_target(
    ctx: &Arc<GpuContext>,
    scene: &str,
    svdag: &Svdag,
    codes: &[u64],
    table: TableArg,
    args: &BenchEditArgs,
) -> Result<BytesRow> {
    let config =
        GpuHashDagConfig::sized_by_load(table.variant()).with_undo_depth(args.random_undo_depth);
    let mut hd = GpuHashDag::load(ctx, &config, svdag, None)?;
    let points = surface_points(codes, args.random_edits.max(1));
    let scale = svdag.resolution as f32 / 8192.0;
    let mut rng = 0x5eed_u64;
    let mut next = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 33) as u32
    };
    let start = Instant::now();
    for p in &points[..args.random_edits] {
        let shape = if next() % 2 == 0 {
            Shape::Sphere
        } else {
            Shape::Cube
        };
        let radius = ((8 + next() % 121) as f32 * scale).max(1.5);
        let tool = if next() % 3 == 0 {
            Tool::Remove {
                shape,
                center: *p,
                radius,
            }
        } else {
            Tool::Add {
                shape,
                center: *p,
                radius,
                material: 0,
            }
        };
        hd.edit(&tool, None)?;
    }
    let edit_s = start.elapsed().as_secs_f64();
    let gc = hd.gc(None)?;
    let image = hd.download()?;
    let mut fresh = HashDag::new(svdag.resolution, false)?;
    for &root in hd.roots() {
        fresh.insert_svdag(&image.to_svdag(root)?, None)?;
    }
    let dag_bytes = live_bytes(&gc.live_per_table);
    let from_scratch_bytes = fresh.item_bytes();
    Ok(BytesRow {
        scene: scene.into(),
        resolution: svdag.resolution,
        table: table.variant().name().into(),
        edits: args.random_edits,
        undo_depth: args.random_undo_depth,
        kept_roots: hd.roots().len(),
        gc_freed_items: gc.freed,
        dag_bytes,
        from_scratch_bytes,
        ratio: dag_bytes as f64 / from_scratch_bytes.max(1) as f64,
        edit_s,
    })
}

/// `voxdag bench edit`.
pub fn bench_edit(args: &BenchEditArgs) -> Result<()> {
    let ctx = GpuContext::new(&GpuOptions::default())?;
    let mut report = Report {
        resolution: args.resolution,
        materials: args.materials,
        cpu_threads: rayon::current_num_threads(),
        device: ctx.info().name.clone(),
        replays: Vec::new(),
        bytes: None,
    };
    for (i, name) in args.scenes.iter().enumerate() {
        let path = scene_path(&args.data, name)?;
        eprintln!("bench edit: {name} at {}^3", args.resolution);
        let options = ImportOptions {
            resolution: Some(args.resolution),
            ..Default::default()
        };
        let voxels = scene::import(&path, &options, &indicatif::ProgressBar::hidden())
            .with_context(|| format!("importing {}", path.display()))?;
        let codes = voxels.codes.clone();
        let mut svdag = Svdag::from_voxels(&voxels)?;
        drop(voxels);
        let materials = match args.materials {
            0 => None,
            k => Some(quantize_materials(&svdag, k)?),
        };
        svdag.colors.clear();
        let palette = materials.as_ref().map(|m| m.palette.len() as u32);
        for replay in replays(&codes, svdag.resolution, args.long_replay, palette) {
            let cpu = run_cpu(name, &svdag, materials.as_ref(), &replay)?;
            let (cpu_ms, cpu_median) = (cpu.edit_ms_total, cpu.edit_ms_median);
            report.replays.push(cpu);
            let engines = args.teams.iter().flat_map(|&team| {
                args.tables
                    .iter()
                    .map(move |&table| GpuEngine { table, team })
            });
            for engine in engines {
                eprintln!("  {} on {}", replay.name, engine.name());
                let mut row = run_gpu(&ctx, name, &svdag, materials.as_ref(), engine, &replay)?;
                if row.status == "ok" {
                    row.vs_cpu = Some(row.edit_ms_total / cpu_ms.max(1e-9));
                    row.median_vs_cpu = Some(row.edit_ms_median / cpu_median.max(1e-9));
                }
                report.replays.push(row);
            }
        }
        if i == 0 && args.random_edits > 0 {
            if let Some(&table) = args.tables.first() {
                eprintln!("  bytes target: {} random edits", args.random_edits);
                report.bytes = Some(bytes_target(&ctx, name, &svdag, &codes, table, args)?);
            }
        }
    }
    let md = markdown(&report);
    print!("{md}");
    write_outputs(&args.json, &report, &args.markdown, &md)
}

fn markdown(report: &Report) -> String {
    let mut md = format!(
        "GPU: {}; CPU reference editor on {} threads; resolution {}^3; {}.\n\n| scene | replay | engine | edits | edit ms total | max | median | profiled ms total | {} | temp SVO max KiB | DAG KiB before | after | / CPU | median / CPU's | per edit: submits / waits / passes |\n|---|---|---|---|---|---|---|---|{}---|---|---|---|---|---|\n",
        report.device,
        report.cpu_threads,
        report.resolution,
        match report.materials {
            0 => "geometry only".to_string(),
            k => format!("materials: colours quantized to at most {k}"),
        },
        GROUPS.join(" ms | ") + " ms",
        "---|".repeat(GROUPS.len()),
    );
    for r in &report.replays {
        if r.status != "ok" {
            md += &format!(
                "| {} | {} | {} | {} | {} |{}\n",
                r.scene,
                r.replay,
                r.engine,
                r.edits,
                r.status,
                " |".repeat(GROUPS.len() + 9)
            );
            continue;
        }
        let kernels: Vec<String> = GROUPS
            .iter()
            .map(|g| {
                r.kernels_ms
                    .get(g)
                    .map_or("-".into(), |ms| format!("{ms:.1}"))
            })
            .collect();
        md += &format!(
            "| {} | {} | {} | {} | {:.1} | {:.1} | {:.2} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.scene,
            r.replay,
            r.engine,
            r.edits,
            r.edit_ms_total,
            r.edit_ms_max,
            r.edit_ms_median,
            r.profiled_ms_total
                .map_or("-".into(), |ms| format!("{ms:.1}")),
            kernels.join(" | "),
            if r.engine == "cpu" {
                "-".into()
            } else {
                format!("{:.0}", r.temp_svo_bytes_max as f64 / 1024.0)
            },
            r.dag_bytes_before / 1024,
            r.dag_bytes_after / 1024,
            r.vs_cpu.map_or("-".into(), |x| format!("{x:.2}x")),
            r.median_vs_cpu.map_or("-".into(), |x| format!("{x:.2}x")),
            r.per_edit
                .map_or("-".into(), |[s, w, p]| format!("{s:.1} / {w:.1} / {p:.0}"))
        );
    }
    if let Some(b) = &report.bytes {
        md += &format!(
            "\nBytes target ({}, {} tables): {} random edits in {:.1} s, undo depth {} ({} kept roots), GC freed {} items: hash DAG {} KiB vs from-scratch {} KiB = {:.3}x (target <= 1.1x).\n",
            b.scene,
            b.table,
            b.edits,
            b.edit_s,
            b.undo_depth,
            b.kept_roots,
            b.gc_freed_items,
            b.dag_bytes / 1024,
            b.from_scratch_bytes / 1024,
            b.ratio
        );
    }
    md
}
