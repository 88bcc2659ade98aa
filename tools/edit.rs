//! `voxdag edit`: replays a HashDAG replay file on a scene and saves the result, on the GPU
//! hash DAG (default) or the CPU reference editor (`--cpu`).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use serde::Serialize;
use voxdag::attr::Materials;
use voxdag::dag::encode::EncodedDag;
use voxdag::dag::{Svdag, VdagFile};
use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::gpu::{GpuHashDag, GpuHashDagConfig};
use voxdag::edit::gpu_gc::GcStats;
use voxdag::edit::item::Root;
use voxdag::edit::replay::{Replay, Step};
use voxdag::edit::tool::Tool;
use voxdag::edit::walk::{self, StoredDag};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::hash::{HashVariant, TeamMode};
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{Camera, RenderSettings};

use crate::commands::{check_output, write_json};

/// Slab layout of the GPU hash DAG's tables.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TableArg {
    /// 64-bit CAS on the slot prefix.
    Atomic64,
    /// Occupancy mask per slab.
    #[value(name = "ticket_board")]
    TicketBoard,
    /// Ticket Board plus a 32-bit secondary hash per slot.
    Accel32,
    /// Ticket Board plus an 8-bit secondary hash per slot.
    Accel8,
}

impl TableArg {
    /// The table variant.
    pub fn variant(self) -> HashVariant {
        match self {
            TableArg::Atomic64 => HashVariant::Atomic64,
            TableArg::TicketBoard => HashVariant::TicketBoard,
            TableArg::Accel32 => HashVariant::AccelHash32,
            TableArg::Accel8 => HashVariant::AccelHash8,
        }
    }
}

/// Lanes per item in the GPU hash DAG's table passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TeamArg {
    /// A subgroup per item: the dedup table and `mark`.
    Subgroup,
    /// A lane per item: the claim passes and the merge's chain of small levels.
    #[value(name = "single-lane")]
    SingleLane,
}

impl TeamArg {
    /// The team mode of the tables.
    pub fn mode(self) -> TeamMode {
        match self {
            TeamArg::Subgroup => TeamMode::Subgroup,
            TeamArg::SingleLane => TeamMode::SingleLane,
        }
    }

    /// Name in reports.
    pub fn name(self) -> &'static str {
        match self {
            TeamArg::Subgroup => "subgroup",
            TeamArg::SingleLane => "single-lane",
        }
    }
}

/// Arguments of `voxdag edit`.
#[derive(Args)]
pub struct EditArgs {
    /// The scene to edit (.vdag, any encoding).
    scene: PathBuf,
    /// HashDAG replay file (CSV) with the edits.
    #[arg(long)]
    replay: PathBuf,
    /// Output .vdag file (svdag32; compress it with `voxdag build`'s encoders afterwards).
    #[arg(long, short)]
    output: PathBuf,
    /// Material id (0..16) of added, painted and filled voxels.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..16))]
    material: u8,
    /// Depth (log2 of the grid side) the replay was recorded at; positions are scaled by
    /// 2^(scene depth - replay depth). Default: the scene's.
    #[arg(long)]
    replay_depth: Option<u32>,
    /// Undo steps kept.
    #[arg(long, default_value_t = 64)]
    undo_depth: usize,
    /// Run the CPU reference editor instead of the GPU hash DAG.
    #[arg(long)]
    cpu: bool,
    /// Slab layout of the GPU hash DAG's tables.
    #[arg(long, value_enum, default_value_t = TableArg::Accel32)]
    table: TableArg,
    /// Lanes per item in the table passes (single lanes: the faster merge on lavapipe and on
    /// an H200 alike; subgroup teams: the dissertation's).
    #[arg(long, value_enum, default_value_t = TeamArg::SingleLane)]
    team: TeamArg,
    /// Print the GPU profile (per-pass times) at the end; the report gets per-edit kernel times.
    #[arg(long)]
    profile: bool,
    /// Write the GPU profiler's Chrome trace (open in Perfetto).
    #[arg(long)]
    trace: Option<PathBuf>,
    /// Render the final scene to this PNG (GPU: the live hash DAG, traversed in place).
    #[arg(long)]
    render_after: Option<PathBuf>,
    /// Write a JSON report (per-edit times, GC, unique nodes per level at the end).
    #[arg(long)]
    report: Option<PathBuf>,
}

/// One replayed edit in the report.
#[derive(Serialize)]
struct EditTime {
    /// Replay line.
    line: usize,
    /// Tool name.
    tool: &'static str,
    /// Wall time in milliseconds.
    ms: f64,
    /// GPU milliseconds per pass name (`--profile`, GPU only).
    #[serde(skip_serializing_if = "Option::is_none")]
    kernels_ms: Option<BTreeMap<String, f64>>,
    /// Temporary SVO entries per level, index = level (GPU only): the edit's size.
    #[serde(skip_serializing_if = "Option::is_none")]
    temporary_nodes: Option<Vec<u32>>,
    /// Items built per level before deduplication (GPU only).
    #[serde(skip_serializing_if = "Option::is_none")]
    items: Option<Vec<u32>>,
}

/// What `voxdag edit --report` writes.
#[derive(Serialize)]
struct EditReport {
    scene: PathBuf,
    replay: PathBuf,
    resolution: u32,
    replay_depth: u32,
    editor: &'static str,
    /// GPU table layout (GPU only).
    #[serde(skip_serializing_if = "Option::is_none")]
    table: Option<&'static str>,
    /// Lanes per item of the table passes, as asked (GPU only).
    #[serde(skip_serializing_if = "Option::is_none")]
    team: Option<&'static str>,
    threads: usize,
    undo_depth: usize,
    load_ms: f64,
    /// GPU only: making the edit pipelines of the replay's tools and the collection's, after
    /// the load and before the first edit (each is otherwise made by the first edit with its
    /// tool, and the collection's by the first GC).
    #[serde(skip_serializing_if = "Option::is_none")]
    pipelines_ms: Option<f64>,
    edits: Vec<EditTime>,
    undos: usize,
    redos: usize,
    edit_ms_total: f64,
    /// Automatic collections during the replay (GPU only).
    auto_gc: Vec<GcReport>,
    /// The final collection from every live root.
    gc: GcReport,
    items_after_gc: u64,
    item_bytes_after_gc: u64,
    /// Unique stored items reachable from the current root, per level (index 0 = leaves).
    unique_nodes_per_level: Vec<u64>,
}

/// One garbage collection in the report.
#[derive(Serialize, Default)]
struct GcReport {
    ms: f64,
    live_items: u64,
    freed_items: u64,
    /// GPU only: items kept per table (index = item words - 2).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    live_per_table: Vec<u64>,
    /// GPU only: slabs returned to the allocators.
    freed_slabs: u64,
    /// GPU only: device bytes of the allocated slabs after.
    slab_bytes_after: u64,
}

impl From<&GcStats> for GcReport {
    fn from(s: &GcStats) -> GcReport {
        GcReport {
            ms: s.ms,
            live_items: s.live,
            freed_items: s.freed,
            live_per_table: s.live_per_table.clone(),
            freed_slabs: s.freed_slabs,
            slab_bytes_after: s.slab_bytes_after,
        }
    }
}

/// The name of a tool in reports.
pub fn tool_name(tool: &Tool) -> &'static str {
    match tool {
        Tool::Add { .. } => "add",
        Tool::Remove { .. } => "remove",
        Tool::Paint { .. } => "paint",
        Tool::Fill { .. } => "fill",
        Tool::Copy(_) => "copy",
    }
}

/// `voxdag edit`.
pub fn edit(args: &EditArgs) -> Result<()> {
    check_output(&args.output)?;
    for path in [&args.report, &args.trace, &args.render_after]
        .into_iter()
        .flatten()
    {
        check_output(path)?;
    }
    let replay = Replay::load(&args.replay)?;
    // A material scene (`build --materials`) is edited with its materials (docs/materials.md).
    // Colours are not edited (dropped on save, below): chunked ones stay encoded.
    let mut file = VdagFile::load_encoded_colors(&args.scene)?;
    let materials = file.materials.take();
    let has_colors = !file.colors.is_empty() || file.stored_colors.is_some();
    let svdag = file.into_svdag(&args.scene)?;
    if let Some(m) = &materials {
        if args.material as usize >= m.palette.len() {
            bail!(
                "--material {} is not in the scene's {}-entry palette",
                args.material,
                m.palette.len()
            );
        }
    }
    let depth = svdag.resolution.trailing_zeros();
    let replay_depth = args.replay_depth.unwrap_or(depth);
    // Every line is checked before the first edit: a bad line applies nothing.
    let steps = replay.steps(svdag.resolution, replay_depth, args.material)?;
    if has_colors {
        log::warn!(
            "{}: the edited scene is saved without its colours (materials come with `build \
             --materials`)",
            args.scene.display()
        );
    }
    let mut report = EditReport {
        scene: args.scene.clone(),
        replay: args.replay.clone(),
        resolution: svdag.resolution,
        replay_depth,
        editor: if args.cpu { "cpu" } else { "gpu" },
        table: (!args.cpu).then(|| args.table.variant().name()),
        team: (!args.cpu).then(|| args.team.name()),
        threads: rayon::current_num_threads(),
        undo_depth: args.undo_depth,
        load_ms: 0.0,
        pipelines_ms: None,
        edits: Vec::new(),
        undos: 0,
        redos: 0,
        edit_ms_total: 0.0,
        auto_gc: Vec::new(),
        gc: GcReport::default(),
        items_after_gc: 0,
        item_bytes_after_gc: 0,
        unique_nodes_per_level: Vec::new(),
    };
    if args.cpu {
        edit_cpu(args, svdag, materials, steps, &mut report)?;
    } else {
        edit_gpu(args, svdag, materials, steps, &mut report)?;
    }
    report.edit_ms_total = report.edits.iter().map(|e| e.ms).sum();
    println!(
        "{} edits ({} undo, {} redo) in {:.1} ms ({} editor{}); GC {:.1} ms freed {} items; {} \
         unique nodes; wrote {}",
        report.edits.len(),
        report.undos,
        report.redos,
        report.edit_ms_total,
        report.editor,
        report
            .table
            .map_or(format!(", {} threads", report.threads), |t| format!(
                ", {t} tables"
            )),
        report.gc.ms,
        report.gc.freed_items,
        report.unique_nodes_per_level.iter().sum::<u64>(),
        args.output.display()
    );
    if let Some(path) = &args.report {
        write_json(path, &report)?;
    }
    Ok(())
}

/// Writes the edited scene: the compact svdag32 DAG, with the palette and the per-voxel ids
/// (depth-first order) of a material scene. Both editors save through here, so their files are
/// byte-identical when their voxels are.
fn save_edited(
    path: &std::path::Path,
    dag: Svdag,
    palette: Option<&[u32]>,
    edited: (&impl StoredDag, Root),
) -> Result<()> {
    match palette {
        None => dag.save(path)?,
        Some(palette) => {
            // One id per voxel is the file format's; streamed, never (code, id) pairs.
            let mut ids = Vec::new();
            walk::for_each_voxel(edited.0, edited.1, |_, id| ids.push(id))?;
            VdagFile {
                encoded: EncodedDag::Svdag32(dag),
                colors: Vec::new(),
                digest: None,
                stored_colors: None,
                materials: Some(Materials::new(palette.to_vec(), ids)?),
            }
            .save(path)?
        }
    }
    Ok(())
}

fn edit_cpu(
    args: &EditArgs,
    svdag: Svdag,
    materials: Option<Materials>,
    steps: Vec<(usize, Step)>,
    report: &mut EditReport,
) -> Result<()> {
    let start = Instant::now();
    let mut dag = HashDag::new(svdag.resolution, materials.is_some())?;
    let root = dag.insert_svdag(&svdag, materials.as_ref().map(|m| m.ids.as_slice()))?;
    drop(svdag);
    report.load_ms = start.elapsed().as_secs_f64() * 1e3;
    let mut editor = CpuEditor::new(dag, root, args.undo_depth);
    for (line, step) in steps {
        match step {
            Step::Edit(tool) => {
                let start = Instant::now();
                editor
                    .edit(&tool)
                    .with_context(|| format!("{}:{line}", args.replay.display()))?;
                report.edits.push(EditTime {
                    line,
                    tool: tool_name(&tool),
                    ms: start.elapsed().as_secs_f64() * 1e3,
                    kernels_ms: None,
                    temporary_nodes: None,
                    items: None,
                });
            }
            Step::Undo => report.undos += editor.undo() as usize,
            Step::Redo => report.redos += editor.redo() as usize,
            Step::EndFrame => {}
        }
    }
    let start = Instant::now();
    let gc = editor.gc()?;
    report.gc = GcReport {
        ms: start.elapsed().as_secs_f64() * 1e3,
        live_items: gc.live,
        freed_items: gc.freed,
        ..GcReport::default()
    };
    report.unique_nodes_per_level = editor.unique_nodes_per_level()?;
    report.items_after_gc = editor.dag().item_count();
    report.item_bytes_after_gc = editor.dag().item_bytes();
    let out = editor.dag().to_svdag(editor.root())?;
    save_edited(
        &args.output,
        out.clone(),
        materials.as_ref().map(|m| m.palette.as_slice()),
        (editor.dag(), editor.root()),
    )?;
    if let Some(png) = &args.render_after {
        let ctx = GpuContext::new(&GpuOptions::default())?;
        let renderer = GpuRenderer::new(&ctx)?;
        let scene = renderer.upload(&out)?;
        let image = renderer.render(&scene, &render_settings(&out), None)?;
        image.save_png(png)?;
        println!("{}: rendered (svdag32 of the result)", png.display());
    }
    Ok(())
}

/// The render of `--render-after`: 1024x768, the default orbit camera framing the scene.
fn render_settings(dag: &Svdag) -> RenderSettings {
    let camera = match dag.occupied_bounds() {
        Some((min, max)) => Camera::orbit(min.map(|v| v as f32), max.map(|v| v as f32)),
        None => Camera::orbit_default(dag.resolution),
    };
    RenderSettings::new(1024, 768, camera)
}

/// GPU milliseconds per pass name of the passes from `from` on.
fn kernel_times(profiler: &Profiler, from: usize) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    for p in &profiler.passes()[from..] {
        *out.entry(p.name.clone()).or_insert(0.0) += p.gpu_ms;
    }
    out
}

fn edit_gpu(
    args: &EditArgs,
    svdag: Svdag,
    materials: Option<Materials>,
    steps: Vec<(usize, Step)>,
    report: &mut EditReport,
) -> Result<()> {
    let ctx = GpuContext::new(&GpuOptions::default())?;
    let mut profiler = if args.profile || args.trace.is_some() {
        Some(Profiler::new(&ctx)?)
    } else {
        None
    };
    let config = GpuHashDagConfig {
        team: args.team.mode(),
        ..GpuHashDagConfig::sized_by_load(args.table.variant()).with_undo_depth(args.undo_depth)
    };
    let start = Instant::now();
    let mut hd = match &materials {
        Some(m) => GpuHashDag::load_materials(&ctx, &config, &svdag, m, profiler.as_mut())?,
        None => GpuHashDag::load(&ctx, &config, &svdag, profiler.as_mut())?,
    };
    report.load_ms = start.elapsed().as_secs_f64() * 1e3;
    drop(svdag);
    let tools = steps.iter().filter_map(|(_, step)| match step {
        Step::Edit(tool) => Some(tool),
        _ => None,
    });
    report.pipelines_ms = Some(hd.prepare_tools(tools)? + hd.prepare_gc()?);
    for (line, step) in steps {
        match step {
            Step::Edit(tool) => {
                let from = profiler.as_ref().map_or(0, |p| p.passes().len());
                let start = Instant::now();
                let edit = hd
                    .edit(&tool, profiler.as_mut())
                    .with_context(|| format!("{}:{line}", args.replay.display()))?;
                let ms = start.elapsed().as_secs_f64() * 1e3;
                report
                    .auto_gc
                    .extend(hd.take_auto_gc().iter().map(GcReport::from));
                report.edits.push(EditTime {
                    line,
                    tool: tool_name(&tool),
                    ms,
                    kernels_ms: profiler.as_ref().map(|p| kernel_times(p, from)),
                    temporary_nodes: Some(edit.temporary_nodes),
                    items: Some(edit.items),
                });
            }
            Step::Undo => report.undos += hd.undo() as usize,
            Step::Redo => report.redos += hd.redo() as usize,
            Step::EndFrame => {}
        }
    }
    let gc = hd.gc(profiler.as_mut())?;
    report.gc = GcReport::from(&gc);
    let image = hd.download()?;
    report.unique_nodes_per_level = image.level_counts(hd.root())?;
    report.items_after_gc = gc.live;
    report.item_bytes_after_gc = gc
        .live_per_table
        .iter()
        .enumerate()
        .map(|(t, &n)| n * 4 * (t as u64 + 2))
        .sum();
    let out = image.to_svdag(hd.root())?;
    save_edited(
        &args.output,
        out.clone(),
        materials.as_ref().map(|m| m.palette.as_slice()),
        (&image, hd.root()),
    )?;
    if let Some(png) = &args.render_after {
        let renderer = GpuRenderer::new(&ctx)?;
        // The material palette (RGBA8 words) as the renderer's RGB bytes.
        let palette = hd
            .palette()
            .map(|p| p.map(|c| [c as u8, (c >> 8) as u8, (c >> 16) as u8]));
        let scene = renderer.bind_hash_dag(&hd, palette.as_ref())?;
        let image = renderer.render(&scene, &render_settings(&out), profiler.as_mut())?;
        image.save_png(png)?;
        println!("{}: rendered from the live hash DAG", png.display());
    }
    if let Some(p) = &profiler {
        if args.profile {
            print!("{}", p.table());
        }
    }
    if let (Some(p), Some(path)) = (&profiler, &args.trace) {
        p.write_chrome_trace(path)?;
        println!(
            "{}: Chrome trace written (open in Perfetto)",
            path.display()
        );
    }
    Ok(())
}
