//! `voxdag bench ooc`: out-of-core path tracing with and without SVDAG proxies on a generated
//! scene (`--kind landscape|forest`). Figure 6.3: disk bytes read (and wall time) with and without proxies at several
//! memory budgets; Figure 6.2: proxy memory and batching events per proxy resolution. Every
//! proxies-on image is checked bit for bit against the proxies-off image of the same budget.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use clap::Args;
use indicatif::ProgressBar;
use serde::Serialize;
use voxdag::ooc::{
    format, prepare, render_out_of_core, OocScene, PrepareOptions, ProxySet, RenderOptions,
    RenderStats,
};

use super::write_outputs;
use crate::commands::peak_rss_bytes;
use crate::ooc::GeneratedSceneArgs;

/// Arguments of `voxdag bench ooc`.
#[derive(Args)]
pub struct BenchOocArgs {
    /// Triangles of the generated scene.
    #[arg(long, default_value_t = 4_000_000)]
    triangles: u64,
    #[command(flatten)]
    generated: GeneratedSceneArgs,
    /// Triangles per batching point.
    #[arg(long, default_value_t = 50_000)]
    batch_triangles: u32,
    /// Scene directory: reused when it holds a scene, else generated there.
    #[arg(long, default_value = "out/bench-ooc-scene")]
    scene: PathBuf,
    /// Memory budgets as fractions of the geometry file (Figure 6.3).
    #[arg(long, value_delimiter = ',', default_value = "0.05,0.1,0.25,0.5")]
    budgets: Vec<f64>,
    /// Proxy resolution of Figure 6.3.
    #[arg(long, default_value_t = 128)]
    proxy_resolution: u32,
    /// Proxy resolutions of Figure 6.2.
    #[arg(long, value_delimiter = ',', default_value = "32,64,128,256,512")]
    resolutions: Vec<u32>,
    /// Budget fraction of Figure 6.2.
    #[arg(long, default_value_t = 0.25)]
    resolution_budget: f64,
    /// Image size WIDTHxHEIGHT.
    #[arg(long, default_value = "128x96", value_parser = crate::commands::parse_size)]
    size: (u32, u32),
    /// Paths per pixel.
    #[arg(long, default_value_t = 2)]
    spp: u32,
    /// Rays in flight.
    #[arg(long, default_value_t = 1 << 16)]
    rays_in_flight: usize,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-ooc.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-ooc.md")]
    markdown: PathBuf,
}

impl BenchOocArgs {
    /// The output files, checked before the work starts.
    pub(super) fn outputs(&self) -> Vec<&Path> {
        vec![self.json.as_path(), self.markdown.as_path()]
    }
}

/// One budget of Figure 6.3.
#[derive(Serialize)]
struct BudgetRow {
    budget_fraction: f64,
    memory_budget: u64,
    off: RenderStats,
    on: Option<RenderStats>,
    disk_ratio: Option<f64>,
    wall_ratio: Option<f64>,
}

/// One resolution of Figure 6.2.
#[derive(Serialize)]
struct ResolutionRow {
    resolution: u32,
    proxy_bytes: u64,
    stats: Option<RenderStats>,
}

/// The whole run.
#[derive(Serialize)]
struct OocReport {
    triangles: u64,
    points: usize,
    geometry_bytes: u64,
    prepare_s: Option<f64>,
    threads: usize,
    width: u32,
    height: u32,
    spp: u32,
    budgets: Vec<BudgetRow>,
    resolutions: Vec<ResolutionRow>,
    peak_rss_bytes: u64,
}

/// Runs the benchmark.
pub fn bench_ooc(args: &BenchOocArgs, quiet: bool) -> Result<()> {
    let mut resolutions = args.resolutions.clone();
    if !resolutions.contains(&args.proxy_resolution) {
        resolutions.push(args.proxy_resolution);
    }
    let mut prepare_s = None;
    if !args.scene.join(format::INDEX_FILE).is_file() {
        let source = args.generated.source(args.triangles)?;
        let options = PrepareOptions {
            batch_triangles: args.batch_triangles,
            proxy_resolutions: resolutions.clone(),
            ..Default::default()
        };
        let start = std::time::Instant::now();
        prepare(
            &source,
            &args.scene,
            &options,
            &crate::commands::progress_bar(quiet),
        )?;
        prepare_s = Some(start.elapsed().as_secs_f64());
    }
    let scene = OocScene::open(&args.scene)?;
    let n = scene.points.len() as u32;
    let render = |budget: u64, proxies: Option<&ProxySet>| {
        let opts = RenderOptions {
            width: args.size.0,
            height: args.size.1,
            spp: args.spp,
            memory_budget: budget,
            rays_in_flight: args.rays_in_flight,
            ..Default::default()
        };
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            crate::commands::progress_bar(false)
        };
        render_out_of_core(&scene, proxies, &opts, &bar)
    };
    let main_proxies = ProxySet::read(
        &args.scene.join(format::proxy_file(args.proxy_resolution)),
        n,
    )?;
    let mut budgets = Vec::new();
    let mut md = format!(
        "Scene: {} triangles, {} batching points, geometry.bin {:.1} MiB; image {}x{}, {} spp, {} threads.\n\n\
         Figure 6.3 (proxies {}^3, {:.1} MiB):\n\n\
         | budget | disk MiB off | disk MiB on | off/on | wall s off | wall s on | off/on | events off | events on | misses off | misses on | empty off | empty on |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        scene.triangles,
        n,
        scene.geometry_bytes as f64 / 1048576.0,
        args.size.0,
        args.size.1,
        args.spp,
        rayon::current_num_threads(),
        args.proxy_resolution,
        main_proxies.bytes() as f64 / 1048576.0
    );
    for &frac in &args.budgets {
        let budget = (scene.geometry_bytes as f64 * frac) as u64;
        let (off_image, off) = render(budget, None)?;
        let on = if main_proxies.bytes() < budget {
            match render(budget, Some(&main_proxies)) {
                Ok((image, stats)) => {
                    if image != off_image {
                        bail!("budget {frac}: the image with proxies differs from the one without");
                    }
                    Some(stats)
                }
                Err(voxdag::ooc::OocError::Invalid(why)) => {
                    eprintln!("budget {frac} with proxies: {why}");
                    None
                }
                Err(e) => return Err(e.into()),
            }
        } else {
            None
        };
        let disk_ratio = on
            .as_ref()
            .map(|s| off.disk_bytes_read as f64 / s.disk_bytes_read.max(1) as f64);
        let wall_ratio = on.as_ref().map(|s| off.wall_s / s.wall_s);
        let cell = |v: Option<String>| v.unwrap_or_else(|| "-".into());
        md += &format!(
            "| {:.0} MiB ({frac}) | {:.1} | {} | {} | {:.2} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            budget as f64 / 1048576.0,
            off.disk_bytes_read as f64 / 1048576.0,
            cell(
                on.as_ref()
                    .map(|s| format!("{:.1}", s.disk_bytes_read as f64 / 1048576.0))
            ),
            cell(disk_ratio.map(|r| format!("{r:.2}x"))),
            off.wall_s,
            cell(on.as_ref().map(|s| format!("{:.2}", s.wall_s))),
            cell(wall_ratio.map(|r| format!("{r:.2}x"))),
            off.batching_events,
            cell(on.as_ref().map(|s| s.batching_events.to_string())),
            off.cache_misses,
            cell(on.as_ref().map(|s| s.cache_misses.to_string())),
            off.empty_batches,
            cell(on.as_ref().map(|s| s.empty_batches.to_string())),
        );
        budgets.push(BudgetRow {
            budget_fraction: frac,
            memory_budget: budget,
            off,
            on,
            disk_ratio,
            wall_ratio,
        });
    }
    let budget = (scene.geometry_bytes as f64 * args.resolution_budget) as u64;
    md += &format!(
        "\nFigure 6.2 (budget {:.0} MiB = {} of the geometry):\n\n| proxy resolution | proxy MiB | batching events | disk MiB | wall s |\n|---|---|---|---|---|\n",
        budget as f64 / 1048576.0,
        args.resolution_budget
    );
    let mut rows = Vec::new();
    for &r in &args.resolutions {
        let set = ProxySet::read(&args.scene.join(format::proxy_file(r)), n)?;
        let stats = if set.bytes() < budget {
            Some(render(budget, Some(&set))?.1)
        } else {
            None
        };
        md += &match &stats {
            Some(s) => format!(
                "| {r} | {:.2} | {} | {:.1} | {:.2} |\n",
                set.bytes() as f64 / 1048576.0,
                s.batching_events,
                s.disk_bytes_read as f64 / 1048576.0,
                s.wall_s
            ),
            None => format!(
                "| {r} | {:.2} | - (proxies do not fit the budget) | - | - |\n",
                set.bytes() as f64 / 1048576.0
            ),
        };
        rows.push(ResolutionRow {
            resolution: r,
            proxy_bytes: set.bytes(),
            stats,
        });
    }
    print!("{md}");
    let report = OocReport {
        triangles: scene.triangles,
        points: scene.points.len(),
        geometry_bytes: scene.geometry_bytes,
        prepare_s,
        threads: rayon::current_num_threads(),
        width: args.size.0,
        height: args.size.1,
        spp: args.spp,
        budgets,
        resolutions: rows,
        peak_rss_bytes: peak_rss_bytes(),
    };
    write_outputs(&args.json, &report, &args.markdown, &md)
}
