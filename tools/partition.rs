//! `voxdag build --part i/K` and `voxdag merge` (docs/scaling.md): the partitioned build, one
//! process per part (a job array on a scheduler), then one merge.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use voxdag::dag::partition::{self, PartBuilder, PartPlan};
use voxdag::scene::{self, voxelize, ImportOptions, Source};

use crate::commands::{check_output, peak_rss_bytes, progress_bar};
use crate::{BuildArgs, EncodingArg};

/// Arguments of `voxdag merge`.
#[derive(Args)]
pub struct MergeArgs {
    /// The part files of one build (`voxdag build --part i/K`), each part exactly once, any order.
    #[arg(required = true)]
    parts: Vec<PathBuf>,
    /// Output .vdag file (svdag32).
    #[arg(long, short)]
    output: PathBuf,
}

/// Parses `--part i/K` (0 <= i < K).
pub fn parse_part(text: &str) -> Result<(u32, u32), String> {
    let (i, k) = text
        .split_once('/')
        .ok_or_else(|| format!("{text:?}: expected i/K, e.g. 3/8"))?;
    let i: u32 = i
        .trim()
        .parse()
        .map_err(|e| format!("{text:?}: index: {e}"))?;
    let k: u32 = k
        .trim()
        .parse()
        .map_err(|e| format!("{text:?}: count: {e}"))?;
    if k == 0 || i >= k {
        return Err(format!("{text:?}: need 0 <= i < K"));
    }
    Ok((i, k))
}

/// `voxdag build --part i/K`: builds part `i` of `K` and writes it to the output (`.vdagp`).
pub fn build_part(args: &BuildArgs, (index, count): (u32, u32), quiet: bool) -> Result<()> {
    if args.encoding != EncodingArg::Svdag32 {
        bail!(
            "--part: the merge writes svdag32; encode the merged file afterwards (docs/scaling.md)"
        );
    }
    let options = ImportOptions {
        resolution: args.resolution,
        vox_scale: args.vox_scale,
        texture_override: args.texture.clone(),
    };
    let codec = args.colors.0.filter(|_| !args.no_colors);
    let bar = progress_bar(quiet);
    let start = Instant::now();
    let builder = |resolution: u32, colors: bool| -> Result<PartBuilder> {
        let plan = PartPlan::new(resolution, index, count)?;
        Ok(PartBuilder::new(
            plan,
            codec.filter(|_| colors).map(|c| (c, args.chunk_depth)),
        )?)
    };
    let part = match scene::open_in(&args.input, &options, args.asset_root.as_deref())? {
        Source::Voxels(voxels) => {
            let mut part = builder(voxels.resolution, voxels.has_colors())?;
            part.push(&voxels.codes, &voxels.colors)?;
            part
        }
        Source::Mesh { mesh, resolution } => {
            let mut part = builder(resolution, mesh.has_colors)?;
            let range = part.plan().codes.clone();
            bar.set_message(format!("part {index}/{count}"));
            voxelize::voxelize_stream_range(&mesh, resolution, range, &bar, |codes, colors| {
                part.push(codes, colors).map_err(anyhow::Error::from)
            })?;
            part
        }
    };
    bar.finish_and_clear();
    let plan = part.plan().clone();
    let summary = part
        .write(&args.output)
        .with_context(|| format!("writing {}", args.output.display()))?;
    println!(
        "{}: part {index}/{count} of {}^3 (subtrees {:?} at level {}): {} voxels, {} nodes, \
         {} subtrees ({:.2} s, peak {:.0} MiB)",
        args.output.display(),
        plan.resolution,
        plan.keys,
        plan.split_level,
        summary.voxels,
        summary.nodes,
        summary.subtrees,
        start.elapsed().as_secs_f64(),
        peak_rss_bytes() as f64 / (1024.0 * 1024.0)
    );
    Ok(())
}

/// `voxdag merge`: the parts' DAGs deduplicated and topped into one `.vdag`.
pub fn merge(args: &MergeArgs) -> Result<()> {
    check_output(&args.output)?;
    let start = Instant::now();
    let s = partition::merge(&args.parts, &args.output)?;
    println!(
        "{}: {} parts merged, {}^3, {} voxels, {} SVDAG nodes, {} bytes ({:.2} s, peak {:.0} MiB)",
        args.output.display(),
        s.parts,
        s.resolution,
        s.voxels,
        s.nodes,
        s.bytes,
        start.elapsed().as_secs_f64(),
        peak_rss_bytes() as f64 / (1024.0 * 1024.0)
    );
    Ok(())
}
