//! `voxdag bench ooc`: out-of-core path tracing with and without SVDAG proxies on a generated
//! scene (`--kind landscape|forest`). Figure 6.3: disk bytes read (and wall time) with and without proxies at several
//! memory budgets; Figure 6.2: proxy memory and batching events per proxy resolution; a policy
//! table: every eviction and schedule policy in both modes at one budget, and each mode at its
//! best policy against the other's. Every proxies-on image is checked bit for bit against the
//! proxies-off image of the same budget (and, in the policy table, against every other).

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use clap::Args;
use indicatif::ProgressBar;
use serde::Serialize;
use voxdag::ooc::{
    format, prepare, render_out_of_core, Eviction, OocScene, PrepareOptions, ProxySet,
    RenderOptions, RenderStats, Schedule,
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
    /// Budget fraction of the policy table (every eviction and schedule policy, the same in
    /// both modes: how much of the ratio is the baseline's policy).
    #[arg(long, default_value_t = 0.25)]
    policy_budget: f64,
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

/// One policy of the policy table: both modes with the same eviction and schedule.
#[derive(Serialize)]
struct PolicyRow {
    eviction: Eviction,
    schedule: Schedule,
    off: RenderStats,
    on: RenderStats,
    disk_ratio: f64,
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
    policy_budget: u64,
    policies: Vec<PolicyRow>,
    /// Bytes without proxies at that mode's best policy over bytes with them at theirs.
    best_against_best: Option<f64>,
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
    let render_with = |budget: u64, proxies: Option<&ProxySet>, eviction, schedule| {
        let opts = RenderOptions {
            width: args.size.0,
            height: args.size.1,
            spp: args.spp,
            memory_budget: budget,
            rays_in_flight: args.rays_in_flight,
            eviction,
            schedule,
            ..Default::default()
        };
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            crate::commands::progress_bar(false)
        };
        render_out_of_core(&scene, proxies, &opts, &bar)
    };
    let render = |budget: u64, proxies: Option<&ProxySet>| {
        render_with(budget, proxies, Eviction::default(), Schedule::default())
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
    let policy_budget = (scene.geometry_bytes as f64 * args.policy_budget) as u64;
    let mut policies = Vec::new();
    if main_proxies.bytes() < policy_budget {
        md += &format!(
            "\nPolicies (budget {:.0} MiB = {} of the geometry, proxies {}^3; the same policy in both modes):\n\n\
             | eviction, schedule | disk MiB off | disk MiB on | off/on | wall s off | wall s on | events off | events on |\n|---|---|---|---|---|---|---|---|\n",
            policy_budget as f64 / 1048576.0,
            args.policy_budget,
            args.proxy_resolution
        );
        let mut reference = None;
        for eviction in [Eviction::Demand, Eviction::Lru] {
            for schedule in [Schedule::Net, Schedule::Fullest] {
                let (off_image, off) = render_with(policy_budget, None, eviction, schedule)?;
                let (on_image, on) =
                    render_with(policy_budget, Some(&main_proxies), eviction, schedule)?;
                let reference = reference.get_or_insert_with(|| off_image.clone());
                if off_image != *reference || on_image != *reference {
                    bail!("{eviction:?}, {schedule:?}: the image differs from the first policy's");
                }
                let disk_ratio = off.disk_bytes_read as f64 / on.disk_bytes_read.max(1) as f64;
                md += &format!(
                    "| {}, {} | {:.1} | {:.1} | {disk_ratio:.2}x | {:.2} | {:.2} | {} | {} |\n",
                    eviction.name(),
                    schedule.name(),
                    off.disk_bytes_read as f64 / 1048576.0,
                    on.disk_bytes_read as f64 / 1048576.0,
                    off.wall_s,
                    on.wall_s,
                    off.batching_events,
                    on.batching_events
                );
                policies.push(PolicyRow {
                    eviction,
                    schedule,
                    off,
                    on,
                    disk_ratio,
                });
            }
        }
    }
    let best = |mode: fn(&PolicyRow) -> &RenderStats| {
        policies
            .iter()
            .min_by_key(|p| mode(p).disk_bytes_read)
            .map(|p| (p, mode(p).disk_bytes_read))
    };
    let best_against_best = match (best(|p| &p.off), best(|p| &p.on)) {
        (Some((off, off_bytes)), Some((on, on_bytes))) => {
            let ratio = off_bytes as f64 / on_bytes.max(1) as f64;
            md += &format!(
                "\nEach mode at its best policy: without proxies {}, {} ({:.1} MiB), with proxies {}, {} ({:.1} MiB): {ratio:.2}x.\n",
                off.eviction.name(),
                off.schedule.name(),
                off_bytes as f64 / 1048576.0,
                on.eviction.name(),
                on.schedule.name(),
                on_bytes as f64 / 1048576.0
            );
            Some(ratio)
        }
        _ => None,
    };
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
        policy_budget,
        policies,
        best_against_best,
        peak_rss_bytes: peak_rss_bytes(),
    };
    write_outputs(&args.json, &report, &args.markdown, &md)
}
