//! `voxdag edit`: replays a HashDAG replay file on a scene and saves the result.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use serde::Serialize;
use voxdag::attr::Materials;
use voxdag::dag::encode::EncodedDag;
use voxdag::dag::VdagFile;
use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::replay::{Replay, Step};
use voxdag::edit::tool::Tool;

use crate::commands::{check_output, seconds, write_json};

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
    /// Run the CPU reference editor (required until the GPU editor is wired into this command).
    #[arg(long)]
    cpu: bool,
    /// Write a JSON report (per-edit times, unique nodes per level at the end).
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
}

/// What `voxdag edit --report` writes.
#[derive(Serialize)]
struct EditReport {
    scene: PathBuf,
    replay: PathBuf,
    resolution: u32,
    replay_depth: u32,
    editor: &'static str,
    threads: usize,
    edits: Vec<EditTime>,
    undos: usize,
    redos: usize,
    edit_ms_total: f64,
    gc_ms: f64,
    gc_freed_items: u64,
    items_after_gc: u64,
    item_bytes_after_gc: u64,
    /// Unique stored items reachable from the current root, per level (index 0 = leaves).
    unique_nodes_per_level: Vec<u64>,
}

fn tool_name(tool: &Tool) -> &'static str {
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
    if !args.cpu {
        bail!(
            "the GPU editor is not wired into `voxdag edit` yet: pass --cpu to run the CPU \
             reference editor"
        );
    }
    check_output(&args.output)?;
    if let Some(report) = &args.report {
        check_output(report)?;
    }
    let replay = Replay::load(&args.replay)?;
    // A material scene (`build --materials`) is edited with its materials (docs/materials.md).
    let mut file = VdagFile::load(&args.scene)?;
    let materials = file.materials.take();
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
    if !svdag.colors.is_empty() {
        log::warn!(
            "{}: the edited scene is saved without its colours (materials come with `build \
             --materials`)",
            args.scene.display()
        );
    }
    let mut dag = HashDag::new(svdag.resolution, materials.is_some())?;
    let root = dag.insert_svdag(&svdag, materials.as_ref().map(|m| m.ids.as_slice()))?;
    drop(svdag);
    let mut editor = CpuEditor::new(dag, root, args.undo_depth);
    let mut edits = Vec::new();
    let (mut undos, mut redos) = (0, 0);
    for (line, step) in steps {
        match step {
            Step::Edit(tool) => {
                let start = Instant::now();
                editor
                    .edit(&tool)
                    .with_context(|| format!("{}:{line}", args.replay.display()))?;
                edits.push(EditTime {
                    line,
                    tool: tool_name(&tool),
                    ms: start.elapsed().as_secs_f64() * 1e3,
                });
            }
            Step::Undo => undos += editor.undo() as usize,
            Step::Redo => redos += editor.redo() as usize,
            Step::EndFrame => {}
        }
    }
    let start = Instant::now();
    let gc = editor.gc()?;
    let gc_time = start.elapsed();
    let unique = editor.unique_nodes_per_level()?;
    let out = editor.dag().to_svdag(editor.root())?;
    let resolution = out.resolution;
    match &materials {
        Some(m) => {
            let ids = editor.dag().voxels(editor.root())?;
            VdagFile {
                encoded: EncodedDag::Svdag32(out),
                colors: Vec::new(),
                digest: None,
                stored_colors: None,
                materials: Some(Materials::new(
                    m.palette.clone(),
                    ids.into_iter().map(|(_, id)| id).collect(),
                )?),
            }
            .save(&args.output)?
        }
        None => out.save(&args.output)?,
    }
    let total: f64 = edits.iter().map(|e| e.ms).sum();
    println!(
        "{} edits ({} undo, {} redo) in {:.1} ms (CPU editor, {} threads); GC {} freed {} items; \
         {} unique nodes; wrote {}",
        edits.len(),
        undos,
        redos,
        total,
        rayon::current_num_threads(),
        seconds(gc_time),
        gc.freed,
        unique.iter().sum::<u64>(),
        args.output.display()
    );
    if let Some(path) = &args.report {
        write_json(
            path,
            &EditReport {
                scene: args.scene.clone(),
                replay: args.replay.clone(),
                resolution,
                replay_depth,
                editor: "cpu",
                threads: rayon::current_num_threads(),
                edits,
                undos,
                redos,
                edit_ms_total: total,
                gc_ms: gc_time.as_secs_f64() * 1e3,
                gc_freed_items: gc.freed,
                items_after_gc: editor.dag().item_count(),
                item_bytes_after_gc: editor.dag().item_bytes(),
                unique_nodes_per_level: unique,
            },
        )?;
    }
    Ok(())
}
