//! `voxdag bench compress`: the dissertation's Tables 3.2-3.4 for our scenes — unique element
//! counts per transform set, encoded bytes per encoding feature, stage times and peak memory.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use image::{Rgb, RgbImage};
use serde::{Deserialize, Serialize};
use voxdag::dag::encode::{
    SsvdagEncoding, TransformGraph, TsvdagEncoding, TsvdagOptions, TsvdagTuning,
};
use voxdag::dag::{CanonicalDag, Invariance, Ssvdag, Svdag, TransformDag, TransformSet};

use super::{scene_path, write_outputs};
use crate::commands::{peak_rss_bytes, read_json, write_json, BuildReport};
use crate::ooc::OnOff;

/// Arguments of `voxdag bench compress`.
#[derive(Args)]
pub struct BenchCompressArgs {
    /// Scenes: shared data set names (bunny, dragon, buddha, sponza-crytek, ...) or paths.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "bunny,dragon,buddha,sponza-crytek"
    )]
    scenes: Vec<String>,
    /// Grid resolutions.
    #[arg(long, value_delimiter = ',', default_value = "2048,4096,8192")]
    resolutions: Vec<u32>,
    /// Folder of the shared data set.
    #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data"))]
    data: PathBuf,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-compress.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-compress.md")]
    markdown: PathBuf,
    /// Bar chart (PNG) of the element counts relative to the SVDAG.
    #[arg(long, default_value = "out/bench-compress.png")]
    chart: PathBuf,
    /// Keep each scene's svdag32 build here (`SCENE-N-svdag32.vdag` with its build report
    /// `SCENE-N-svdag32.json`) and reuse it: at 65536^3 the voxelization alone takes an hour.
    #[arg(long)]
    cache: Option<PathBuf>,
    /// The translation search (S+A+T). `off` leaves the S+A+T column empty and measures the
    /// encodings on S+A: at 65536^3 the search takes hours (docs/translations.md).
    #[arg(long, value_enum, default_value = "on")]
    translations: OnOff,
    /// The encoder-heuristic ablation (12 more TSVDAG encodes; about 20 minutes at 65536^3).
    #[arg(long, value_enum, default_value = "on")]
    heuristics: OnOff,
    /// Internal: measure one scene at one resolution in this process and write its row here.
    #[arg(long, hide = true)]
    row_out: Option<PathBuf>,
    /// Internal: the row's svdag32 file (with `--row-out`).
    #[arg(long, hide = true)]
    svdag: Option<PathBuf>,
    /// Internal: the report of the build that wrote `--svdag`.
    #[arg(long, hide = true)]
    build_report: Option<PathBuf>,
}

impl BenchCompressArgs {
    /// The output files, checked before the work starts (a per-scene child writes only its row).
    pub(super) fn outputs(&self) -> Vec<&std::path::Path> {
        match &self.row_out {
            Some(row) => vec![row.as_path()],
            None => vec![
                self.json.as_path(),
                self.markdown.as_path(),
                self.chart.as_path(),
            ],
        }
    }
}

/// Seconds spent in each stage.
#[derive(Serialize, Deserialize, Default)]
struct StageTimes {
    /// `voxdag build` (streaming) of the svdag32 file, in its own process.
    voxelize_and_build: f64,
    /// Loading the svdag32 file for the stages below.
    load: f64,
    ssvdag: f64,
    s: f64,
    a: f64,
    sa: f64,
    /// The translation search on top of S+A (none with `--translations off`).
    sat: Option<f64>,
    encode_ssvdag: f64,
    encode_tsvdag: f64,
    /// The three modes with the format-v1 encoder's heuristics (`TsvdagTuning::V1`), same run
    /// (none with `--heuristics off`).
    encode_tsvdag_v1: Option<f64>,
}

/// Unique elements (nodes + leaves over all levels) per variant.
#[derive(Serialize, Deserialize, Default)]
struct Elements {
    svo: u64,
    svdag: u64,
    ssvdag: u64,
    s: u64,
    a: u64,
    sa: u64,
    /// None with `--translations off`.
    sat: Option<u64>,
}

/// Encoded bytes per encoding / feature set (TSVDAG on S+A+T, or on S+A without the
/// translation search).
#[derive(Serialize, Deserialize, Default)]
struct Bytes {
    svdag32: u64,
    ssvdag: u64,
    tsvdag_base: u64,
    tsvdag_lut: u64,
    tsvdag: u64,
}

/// TSVDAG bytes per mode with a cumulative set of encoder heuristics (`v1`: none, as the
/// format-v1 encoder; `+reorient`; `+compact`: escape/mask translation fields; `+tie-break`;
/// `+tagged`: tagged 16-bit pointers where cheaper, i.e. all).
#[derive(Serialize, Deserialize)]
struct Ablation {
    heuristics: String,
    base: u64,
    lut: u64,
    huffman: u64,
}

/// One (scene, resolution) measurement.
#[derive(Serialize, Deserialize)]
struct CompressRow {
    scene: String,
    resolution: u32,
    voxels: u64,
    elements: Elements,
    bytes: Bytes,
    seconds: StageTimes,
    /// Peak RSS of the build process (voxelization and SVDAG build).
    build_peak_rss_bytes: u64,
    /// Peak RSS of the process that ran the stages after the build.
    peak_rss_bytes: u64,
    ablation: Vec<Ablation>,
}

impl CompressRow {
    /// The transform set the TSVDAG encodings were measured on.
    fn encoded_set(&self) -> &'static str {
        if self.elements.sat.is_some() {
            "S+A+T"
        } else {
            "S+A"
        }
    }
}

/// Runs `f` and returns its result with the seconds it took.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let start = Instant::now();
    let value = f();
    (value, start.elapsed().as_secs_f64())
}

/// Measures one scene at one resolution in this process, from its svdag32 build.
fn measure(
    scene_name: &str,
    svdag: &Path,
    build: &BuildReport,
    translations: bool,
    heuristics: bool,
) -> Result<CompressRow> {
    // Each stage prints its time: at 65536^3 they take minutes each.
    let stage = |name: &str, seconds: f64| eprintln!("  {name}: {seconds:.1} s");
    let (dag, load_s) = timed(|| Svdag::load(svdag));
    let dag = dag.with_context(|| format!("loading {}", svdag.display()))?;
    stage("load", load_s);
    let stats = dag.stats();
    let total = |counts: Vec<u64>| counts.iter().sum::<u64>();
    let (ssvdag, ssvdag_s) = timed(|| total(Ssvdag::build(&dag, Invariance::Axes3).level_counts()));
    stage("SSVDAG", ssvdag_s);
    let (s, s_s) = timed(|| total(CanonicalDag::build(&dag, TransformSet::Mirrors).level_counts()));
    stage("S", s_s);
    let (a, a_s) =
        timed(|| total(CanonicalDag::build(&dag, TransformSet::AxisPermutations).level_counts()));
    stage("A", a_s);
    let (canonical, sa_s) = timed(|| CanonicalDag::build(&dag, TransformSet::All));
    let sa = total(canonical.level_counts());
    stage("S+A", sa_s);
    let (tdag, translate_s) = timed(|| {
        TransformDag::from_canonical(canonical, translations, &indicatif::ProgressBar::hidden())
    });
    let sat = translations.then(|| total(tdag.level_counts()));
    let sat_s = translations.then_some(translate_s);
    if translations {
        stage("translation search", translate_s);
    }
    let (ssvdag_bytes, encode_ssvdag) =
        timed(|| SsvdagEncoding::build(&dag).map(|e| e.byte_size()));
    stage("encode SSVDAG", encode_ssvdag);
    let graph = TransformGraph::from_transform_dag(tdag);
    let modes = |tuning: TsvdagTuning| -> Result<[u64; 3]> {
        let mut out = [0; 3];
        for (o, &mode) in out.iter_mut().zip(&TsvdagOptions::MODES) {
            *o = TsvdagEncoding::encode_tuned(&graph, mode, tuning)?.byte_size();
        }
        Ok(out)
    };
    // Base, +LUT, +LUT+Huffman with every heuristic (what `TsvdagEncoding::encode` uses).
    let (all, encode_tsvdag) = timed(|| modes(TsvdagTuning::ALL));
    let [base, lut, full] = all?;
    stage("encode TSVDAG", encode_tsvdag);
    let mut ablation = Vec::new();
    let mut encode_tsvdag_v1 = None;
    if heuristics {
        let (v1, v1_s) = timed(|| modes(TsvdagTuning::V1));
        encode_tsvdag_v1 = Some(v1_s);
        stage("encode TSVDAG, v1 heuristics", v1_s);
        let v1 = v1?;
        let mut tuning = TsvdagTuning::V1;
        for step in ["v1", "+reorient", "+compact", "+tie-break", "+tagged"] {
            match step {
                "+reorient" => tuning.reorient = true,
                "+compact" => tuning.compact_translations = true,
                "+tie-break" => tuning.tie_break = true,
                "+tagged" => tuning.tagged_pointers = true,
                _ => {}
            }
            // The first step (v1) and the last (every heuristic) were encoded above.
            let [base, lut, huffman] = if tuning == TsvdagTuning::V1 {
                v1
            } else if tuning == TsvdagTuning::ALL {
                [base, lut, full]
            } else {
                modes(tuning)?
            };
            ablation.push(Ablation {
                heuristics: step.to_string(),
                base,
                lut,
                huffman,
            });
        }
    }
    Ok(CompressRow {
        scene: scene_name.to_string(),
        resolution: stats.resolution,
        voxels: stats.voxels,
        elements: Elements {
            svo: stats.levels.iter().map(|l| l.svo).sum(),
            svdag: stats.levels.iter().map(|l| l.svdag).sum(),
            ssvdag,
            s,
            a,
            sa,
            sat,
        },
        bytes: Bytes {
            svdag32: dag.bytes_svdag32(),
            ssvdag: ssvdag_bytes?,
            tsvdag_base: base,
            tsvdag_lut: lut,
            tsvdag: full,
        },
        seconds: StageTimes {
            voxelize_and_build: build.voxelize_s + build.build_s,
            load: load_s,
            ssvdag: ssvdag_s,
            s: s_s,
            a: a_s,
            sa: sa_s,
            sat: sat_s,
            encode_ssvdag,
            encode_tsvdag,
            encode_tsvdag_v1,
        },
        build_peak_rss_bytes: build.peak_rss_bytes,
        peak_rss_bytes: peak_rss_bytes(),
        ablation,
    })
}

/// `voxdag bench compress`: each (scene, resolution) is built to svdag32 by `voxdag build` (the
/// streaming build, so 65536^3 fits) and measured in a second child process, so that the peak
/// RSS of each is its own.
pub fn bench_compress(args: &BenchCompressArgs) -> Result<()> {
    let translations = args.translations == OnOff::On;
    let heuristics = args.heuristics == OnOff::On;
    let on_off = |on: bool| if on { "on" } else { "off" };
    if let Some(row_out) = &args.row_out {
        let (Some(svdag), Some(report), [name]) =
            (&args.svdag, &args.build_report, args.scenes.as_slice())
        else {
            bail!("--row-out measures exactly one scene from its --svdag and --build-report");
        };
        let build: BuildReport = read_json(report)?;
        let row = measure(name, svdag, &build, translations, heuristics)?;
        return write_json(row_out, &row);
    }
    let exe = std::env::current_exe().context("locating the voxdag executable")?;
    let scratch = tempfile::Builder::new().prefix("voxdag-bench").tempdir()?;
    let builds = match &args.cache {
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            dir.as_path()
        }
        None => scratch.path(),
    };
    let mut rows: Vec<CompressRow> = Vec::new();
    for name in &args.scenes {
        let input = scene_path(&args.data, name)?;
        let stem = input
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| name.clone());
        for &resolution in &args.resolutions {
            eprintln!("bench compress: {name} at {resolution}^3");
            let svdag = builds.join(format!("{stem}-{resolution}-svdag32.vdag"));
            let report = svdag.with_extension("json");
            if svdag.exists() && report.exists() {
                check_cached_build(&report, resolution)?;
                eprintln!("  svdag32 build: cached {}", svdag.display());
            } else {
                super::run_build(&input, resolution, &svdag, &report, true)?;
            }
            let row_path = scratch.path().join("row.json");
            let status = Command::new(&exe)
                .args(["bench", "compress", "--scenes", name])
                .args(["--translations", on_off(translations)])
                .args(["--heuristics", on_off(heuristics)])
                .arg("--svdag")
                .arg(&svdag)
                .arg("--build-report")
                .arg(&report)
                .arg("--row-out")
                .arg(&row_path)
                .status()
                .context("starting voxdag bench compress")?;
            if !status.success() {
                bail!("bench compress of {name} at {resolution} failed ({status})");
            }
            rows.push(read_json(&row_path)?);
            if args.cache.is_none() {
                std::fs::remove_file(&svdag).ok();
            }
        }
    }
    let md = markdown(&rows);
    print!("{md}");
    write_chart(&args.chart, &rows)?;
    write_outputs(&args.json, &rows, &args.markdown, &md)
}

/// Refuses a cached build report of another resolution (a renamed or stale file).
fn check_cached_build(report: &Path, resolution: u32) -> Result<()> {
    let build: BuildReport = read_json(report)?;
    if build.resolution != resolution {
        bail!(
            "{} is a build at {}^3, not {resolution}^3: delete it or use another --cache",
            report.display(),
            build.resolution
        );
    }
    Ok(())
}

/// Tables 3.2 (elements), 3.3 (bytes) and 3.4 (times) as Markdown.
fn markdown(rows: &[CompressRow]) -> String {
    let pct = |x: u64, of: u64| {
        if of == 0 {
            0.0
        } else {
            100.0 * x as f64 / of as f64
        }
    };
    let mut md = String::from("### Unique elements (nodes + leaves; % of SSVDAG)\n\n| scene | N | voxels | SVO | SVDAG | SSVDAG | S | A | S+A | S+A+T |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let e = &r.elements;
        let sat = match e.sat {
            Some(sat) => format!("{sat} ({:.1}%)", pct(sat, e.ssvdag)),
            None => "not run".to_string(),
        };
        md +=
            &format!(
            "| {} | {} | {} | {} | {} | {} | {} ({:.1}%) | {} ({:.1}%) | {} ({:.1}%) | {sat} |\n",
            r.scene, r.resolution, r.voxels, e.svo, e.svdag, e.ssvdag,
            e.s, pct(e.s, e.ssvdag), e.a, pct(e.a, e.ssvdag), e.sa, pct(e.sa, e.ssvdag)
        );
    }
    md += "\n### Encoded bytes (TSVDAG on the set named; % of SSVDAG)\n\n| scene | N | TSVDAG on | SVDAG32 | SSVDAG | Base | +LUT | +LUT+Huffman |\n|---|---|---|---|---|---|---|---|\n";
    for r in rows {
        let b = &r.bytes;
        md += &format!(
            "| {} | {} | {} | {} | {} | {} ({:.1}%) | {} ({:.1}%) | {} ({:.1}%) |\n",
            r.scene,
            r.resolution,
            r.encoded_set(),
            b.svdag32,
            b.ssvdag,
            b.tsvdag_base,
            pct(b.tsvdag_base, b.ssvdag),
            b.tsvdag_lut,
            pct(b.tsvdag_lut, b.ssvdag),
            b.tsvdag,
            pct(b.tsvdag, b.ssvdag)
        );
    }
    md += "\nFor comparison, the dissertation reports for its own voxelizations at 65536^3 TSVDAG bytes (S+A+T, full encoding) at 61-83% of the SSVDAG's, 61% on its bunny.\n";
    if rows.iter().any(|r| !r.ablation.is_empty()) {
        md += "\n### TSVDAG bytes per encoder heuristic (cumulative; best mode in bold)\n\n| scene | N | TSVDAG on | heuristics | Base | +LUT | +LUT+Huffman |\n|---|---|---|---|---|---|---|\n";
    }
    for r in rows {
        for a in &r.ablation {
            let best = a.base.min(a.lut).min(a.huffman);
            let cell = |v: u64| {
                if v == best {
                    format!("**{v}**")
                } else {
                    v.to_string()
                }
            };
            md += &format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                r.scene,
                r.resolution,
                r.encoded_set(),
                a.heuristics,
                cell(a.base),
                cell(a.lut),
                cell(a.huffman)
            );
        }
    }
    md += "\n### Seconds per stage and peak memory\n\n| scene | N | voxelize+build | build peak RSS MiB | load | SSVDAG | S | A | S+A | translation search | encode SSVDAG | encode TSVDAG (3 variants) | same, v1 heuristics | stages peak RSS MiB |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    let mib = |bytes: u64| bytes as f64 / 1048576.0;
    for r in rows {
        let t = &r.seconds;
        let seconds = |s: Option<f64>| s.map_or("not run".to_string(), |s| format!("{s:.2}"));
        let (sat, v1) = (seconds(t.sat), seconds(t.encode_tsvdag_v1));
        md += &format!(
            "| {} | {} | {:.2} | {:.0} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {sat} | {:.2} | {:.2} | {v1} | {:.0} |\n",
            r.scene, r.resolution, t.voxelize_and_build, mib(r.build_peak_rss_bytes), t.load,
            t.ssvdag, t.s, t.a, t.sa, t.encode_ssvdag, t.encode_tsvdag, mib(r.peak_rss_bytes)
        );
    }
    md += "\nChart: per row one group of bars = element counts of SSVDAG, S, A, S+A, S+A+T as a share of the SVDAG's (full height = SVDAG).\n";
    md
}

/// Bar colours of the chart, in the order SSVDAG, S, A, S+A, S+A+T.
const BAR_COLOURS: [[u8; 3]; 5] = [
    [120, 120, 120],
    [66, 133, 244],
    [52, 168, 83],
    [251, 188, 5],
    [234, 67, 53],
];

/// Draws one group of 5 bars per row (heights relative to the row's SVDAG count) as a PNG.
fn write_chart(path: &std::path::Path, rows: &[CompressRow]) -> Result<()> {
    let (bar, gap, height) = (14u32, 18u32, 240u32);
    let width = gap + rows.len() as u32 * (5 * bar + gap);
    let mut img = RgbImage::from_pixel(width, height + 20, Rgb([255, 255, 255]));
    for (i, r) in rows.iter().enumerate() {
        let e = &r.elements;
        // A search not run leaves its bar out.
        let values = [e.ssvdag, e.s, e.a, e.sa, e.sat.unwrap_or(0)];
        for (j, &value) in values.iter().enumerate() {
            let h = (height as f64 * value as f64 / e.svdag.max(1) as f64).round() as u32;
            let x0 = gap + i as u32 * (5 * bar + gap) + j as u32 * bar;
            for x in x0..x0 + bar - 2 {
                for y in (10 + height - h.min(height))..(10 + height) {
                    img.put_pixel(x, y, Rgb(BAR_COLOURS[j]));
                }
            }
        }
    }
    for x in 0..width {
        img.put_pixel(x, 10 + height, Rgb([0, 0, 0]));
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    voxdag::atomic_file::write_atomic(path, |w| {
        img.write_to(w, image::ImageFormat::Png)
            .map_err(std::io::Error::other)
    })
    .with_context(|| format!("writing {}", path.display()))
}
