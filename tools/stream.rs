//! The streaming `voxdag build` (docs/scaling.md): bricks flow from the voxelizer into the
//! per-level deduplication and the colour chunk encoders; only the DAG and a working set are
//! held, and `--memory-budget` bounds both.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use voxdag::dag::encode::DigestBuilder;
use voxdag::dag::stream::{save_streamed, ColorStream, StreamBuilder};
use voxdag::safety::human_bytes;
use voxdag::scene::{self, voxelize, ImportOptions, Source};

use crate::commands::{
    encode_dag, peak_rss_bytes, progress_bar, tsvdag_modes, BuildReport, EncodedSummary,
};
use crate::BuildArgs;

/// Voxels one brick (128^3) is assumed to hand over at most, for the working-set estimate: three
/// full cross-sections (a surface crossing the brick, folded).
const VOXELS_PER_BRICK: f64 = 3.0 * 128.0 * 128.0;

/// Bytes the colour stream holds at most besides its chunk tables: a batch of colours, their
/// encoded and decoded copies, and the spill buffer.
const COLOR_WORKING_SET: u64 = 3 * 4 * (1 << 22) + (1 << 20);

/// The sinks of one streaming build and the budget they are held to.
struct Streaming {
    builder: StreamBuilder,
    colors: Option<ColorStream>,
    digest: DigestBuilder,
    /// `--memory-budget` minus what is held outside the builder and colour stream.
    budget: Option<u64>,
}

impl Streaming {
    /// Takes the next brick's voxels.
    fn feed(&mut self, codes: &[u64], colors: &[u32]) -> Result<()> {
        for &c in codes {
            self.digest.push(c);
        }
        self.builder.push(codes)?;
        if let Some(stream) = &mut self.colors {
            stream.push(codes, colors)?;
        }
        self.check("while building")
    }

    /// Bytes the builder and colour stream hold.
    fn held(&self) -> u64 {
        self.builder.memory_bytes() + self.colors.as_ref().map_or(0, |c| c.memory_bytes())
    }

    /// Fails when what is held passes the budget.
    fn check(&self, when: &str) -> Result<()> {
        if let Some(budget) = self.budget {
            let held = self.held();
            if held > budget {
                bail!(
                    "--memory-budget exceeded {when}: the DAG so far ({} unique nodes after {} \
                     voxels) and the colour chunks hold {}, {} is left for them after the \
                     working set; give a larger budget (docs/scaling.md)",
                    self.builder.nodes(),
                    self.builder.voxels(),
                    human_bytes(held),
                    human_bytes(budget)
                );
            }
        }
        Ok(())
    }
}

/// `voxdag build` without `--in-memory`.
pub fn build_streaming(args: &BuildArgs, quiet: bool) -> Result<()> {
    let options = ImportOptions {
        resolution: args.resolution,
        vox_scale: args.vox_scale,
        texture_override: args.texture.clone(),
    };
    let codec = args.colors.0.filter(|_| !args.no_colors);
    let spill_dir = match args.output.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => Path::new(".").to_path_buf(),
    };
    let bar = progress_bar(quiet);
    let start = Instant::now();
    let streaming = |resolution: u32, colors: bool, budget: Option<u64>| -> Result<Streaming> {
        Ok(Streaming {
            builder: StreamBuilder::new(resolution)?,
            colors: match codec.filter(|_| colors) {
                Some(codec) => Some(ColorStream::new(
                    codec,
                    args.chunk_depth,
                    resolution,
                    &spill_dir,
                )?),
                None => None,
            },
            digest: DigestBuilder::default(),
            budget,
        })
    };
    let mut s = match scene::open_in(&args.input, &options, args.asset_root.as_deref())? {
        Source::Voxels(voxels) => {
            let budget = remaining_budget(args.memory_budget, COLOR_WORKING_SET, 0.0)?;
            let mut s = streaming(voxels.resolution, voxels.has_colors(), budget)?;
            s.feed(&voxels.codes, &voxels.colors)?;
            s
        }
        Source::Mesh { mesh, resolution } => {
            let colors = mesh.has_colors && codec.is_some();
            let working = voxelize::stream_working_set(
                mesh.triangle_count(),
                mesh.has_colors,
                VOXELS_PER_BRICK,
            ) + if colors { COLOR_WORKING_SET } else { 0 };
            let voxels = if args.memory_budget.is_some() {
                voxelize::estimate_voxels(&mesh, resolution)?
            } else {
                0.0
            };
            let budget = remaining_budget(args.memory_budget, working, voxels)?;
            let mut s = streaming(resolution, colors, budget)?;
            bar.set_message("streaming");
            voxelize::voxelize_stream(&mesh, resolution, &bar, |codes, cols| s.feed(codes, cols))?;
            s
        }
    };
    bar.finish_and_clear();
    let stream_time = start.elapsed();
    if let Some(budget) = s.budget {
        // Laying the levels out copies them once: both exist for a moment.
        let layout = s.builder.layout_bytes();
        if layout > budget {
            bail!(
                "--memory-budget exceeded laying out the DAG ({} unique nodes): it needs {}, \
                 {} is left after the working set (docs/scaling.md)",
                s.builder.nodes(),
                human_bytes(layout),
                human_bytes(budget)
            );
        }
    }
    let digest = s.digest.finish();
    let colors = match s.colors.take() {
        Some(c) => c.finish()?,
        None => None,
    };
    let built = s.builder.finish()?;
    let build_time = start.elapsed() - stream_time;
    let stats = built.dag.stats();
    let start = Instant::now();
    let dag_hash = built.dag_hash;
    let encoded = encode_dag(
        built.dag,
        args.encoding,
        args.transforms,
        &tsvdag_modes(args),
        quiet,
    )?;
    let encode_time = start.elapsed();
    let summary = EncodedSummary::of(&encoded);
    if let Some(c) = &colors {
        println!(
            "colours: {} {} -> {} bytes ({:.1}% of RGB888) in {} chunks at depth {}, RMSE {:.4}",
            c.color_count(),
            c.codec.name(),
            c.byte_size(),
            100.0 * c.byte_size() as f64 / (3.0 * c.color_count() as f64),
            c.chunk_count(),
            c.chunk_depth,
            c.rmse,
        );
    }
    save_streamed(
        &args.output,
        &encoded,
        &digest,
        colors,
        built.voxels,
        dag_hash,
    )
    .with_context(|| format!("writing {}", args.output.display()))?;
    let report = BuildReport {
        input: args.input.clone(),
        resolution: stats.resolution,
        voxels: stats.voxels,
        voxelize_s: stream_time.as_secs_f64(),
        build_s: build_time.as_secs_f64(),
        peak_rss_bytes: peak_rss_bytes(),
        stats,
    };
    let timing = format!(
        "voxelize+build streamed {:.2} s, layout {:.2} s",
        report.voxelize_s, report.build_s
    );
    summary.finish(args, &report, &timing, encode_time)
}

/// What `--memory-budget` leaves for the DAG and the colour chunk tables once the process as
/// it is now (binary, mesh: its peak RSS so far) and the streaming `working` set are counted;
/// refuses when that is nothing. `voxels` (the estimated surface voxels) is only reported.
fn remaining_budget(budget: Option<u64>, working: u64, voxels: f64) -> Result<Option<u64>> {
    let Some(budget) = budget else {
        return Ok(None);
    };
    let now = peak_rss_bytes();
    let fixed = now + working;
    if fixed >= budget {
        bail!(
            "--memory-budget {} cannot hold this build: the process already uses {} (binary, \
             mesh) and the streaming working set needs {} more, before any DAG node \
             (about {:.0} M surface voxels); see docs/scaling.md",
            human_bytes(budget),
            human_bytes(now),
            human_bytes(working),
            voxels / 1e6
        );
    }
    Ok(Some(budget - fixed))
}
