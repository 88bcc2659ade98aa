//! `voxdag render --hash-dag [--hash-table VARIANT]`: loads the scene into the GPU hash DAG of
//! the editor (`edit::gpu::GpuHashDag`) and renders it traversed in place
//! (`render::hash_scene`), with the raster shading or `--pt`, so that the editor's live format
//! can be checked from the command line.

use std::time::Instant;

use anyhow::{bail, Context, Result};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::hash::HashVariant;
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::hash_scene::HashDagScene;
use voxdag::render::pathtrace_gpu::{GpuPathTracer, PtMode};

use crate::commands::{load_svdag, render_settings, seconds};
use crate::RenderArgs;

/// The `--hash-table` variant (default Atomic64).
fn variant(name: Option<&str>) -> Result<HashVariant> {
    let Some(name) = name else {
        return Ok(HashVariant::Atomic64);
    };
    HashVariant::ALL
        .into_iter()
        .find(|v| v.name() == name)
        .with_context(|| {
            format!("unknown --hash-table {name:?} (atomic64, ticket_board, accel32, accel8)")
        })
}

/// Renders `args.file` through a hash DAG (flags already checked by `commands::render`).
pub fn render(args: &RenderArgs) -> Result<()> {
    if !args.hash_dag {
        bail!("--hash-table needs --hash-dag");
    }
    if args.cpu {
        bail!("--hash-dag renders the GPU hash DAG: it cannot be combined with --cpu");
    }
    let variant = variant(args.hash_table.as_deref())?;
    let mut dag = load_svdag(&args.file)?;
    if !dag.colors.is_empty() {
        println!("note: the hash DAG holds geometry only; the file's colours are not shown");
        dag.colors = Vec::new();
    }
    let settings = render_settings(args, dag.occupied_bounds(), dag.resolution);
    let context = GpuContext::new(&GpuOptions::default())?;
    let renderer = GpuRenderer::new(&context)?;
    let mut profiler = Profiler::new(&context)?;
    let load_start = Instant::now();
    let loaded = HashDagScene::load(&context, &renderer, &dag, variant, None)?;
    drop(dag);
    println!(
        "hash DAG ({}): loaded in {}, {:.1} MiB of tables",
        variant.name(),
        seconds(load_start.elapsed()),
        loaded.dag.gpu_bytes() as f64 / (1 << 20) as f64
    );
    let start = Instant::now();
    if args.pt.pt {
        let pt = args.pt.settings(settings)?;
        let mode = if args.pt.wavefront {
            PtMode::Wavefront
        } else {
            PtMode::Megakernel
        };
        let tracer = GpuPathTracer::new(&context)?;
        let profiled = args.profile || args.trace.is_some();
        let image = tracer.render(&loaded.scene, &pt, mode, profiled.then_some(&mut profiler))?;
        image.save(&args.out)?;
        finish_profile(args, &profiler)?;
        println!(
            "{}: {}x{}, {} spp, {} bounces in {}",
            args.out.display(),
            pt.render.width,
            pt.render.height,
            pt.spp,
            pt.bounces,
            seconds(start.elapsed())
        );
        return Ok(());
    }
    let image = renderer.render(&loaded.scene, &settings, Some(&mut profiler))?;
    image.save_png(&args.out)?;
    finish_profile(args, &profiler)?;
    println!(
        "{}: {}x{} in {}",
        args.out.display(),
        args.size.0,
        args.size.1,
        seconds(start.elapsed())
    );
    Ok(())
}

/// Prints the profile table and writes the trace when asked.
fn finish_profile(args: &RenderArgs, profiler: &Profiler) -> Result<()> {
    if args.profile {
        print!("{}", profiler.table());
    }
    if let Some(path) = &args.trace {
        profiler.write_chrome_trace(path)?;
        println!(
            "{}: Chrome trace written (open in Perfetto)",
            path.display()
        );
    }
    Ok(())
}
