//! The subcommands of the `voxdag` CLI (everything but the benchmarks).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use serde::{Deserialize, Serialize};
use voxdag::atomic_file::{check_output_path, write_atomic};
use voxdag::attr::{ChunkedColors, ColorCodec, LosslessVariant, Materials, StoredColors};
use voxdag::dag::digest::ContentDigest;
use voxdag::dag::encode::{
    voxel_digest, EncodedDag, SsvdagEncoding, TransformGraph, TsvdagEncoding, TsvdagOptions,
    VoxelDigest,
};
use voxdag::dag::{
    analyze_symmetry, export_vox, export_xyz_u32_file, CanonicalDag, DagStats, Svdag,
    SymmetryAnalysis, TransformDag, TransformSet, VdagFile, VoxelIndex,
};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};
use voxdag::render::cpu::{render_cpu_with, ColorSource};
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{Camera, RenderSettings};
use voxdag::scene::{self, ImportOptions};

use crate::{
    BuildArgs, ColorsArg, DemoArgs, EncodingArg, ExportArgs, ExportFormat, RenderArgs, StatsArgs,
    TransformsArg, TsvdagModeArg, VerifyArgs,
};

/// What `voxdag build --report` writes: the inputs, the outcome and the cost of one build.
#[derive(Serialize, Deserialize)]
pub struct BuildReport {
    /// Input scene path.
    pub input: PathBuf,
    /// Grid resolution.
    pub resolution: u32,
    /// Occupied voxels.
    pub voxels: u64,
    /// Seconds spent importing and voxelizing.
    pub voxelize_s: f64,
    /// Seconds spent building the SVDAG.
    pub build_s: f64,
    /// Peak resident memory of the process in bytes (VmHWM).
    pub peak_rss_bytes: u64,
    /// Node counts and bytes of the result.
    pub stats: DagStats,
}

/// A progress bar with voxdag's style, hidden when `quiet`.
pub fn progress_bar(quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg:>12} [{elapsed_precise}] {wide_bar} {pos}/{len} ({eta})",
        )
        .expect("valid progress template"),
    );
    bar
}

/// Peak resident set size of this process in bytes, from /proc/self/status (0 if unavailable).
pub fn peak_rss_bytes() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| {
            let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
            let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
            Some(kib * 1024)
        })
        .unwrap_or(0)
}

/// Parses "WIDTHxHEIGHT".
pub fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or("expected WIDTHxHEIGHT, e.g. 1024x768")?;
    let parse = |s: &str| {
        s.trim()
            .parse::<u32>()
            .map_err(|e| format!("bad size {s:?}: {e}"))
    };
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!(
            "image size {w}x{h} out of range (1..=16384 per side)"
        ));
    }
    Ok((w, h))
}

/// Parses a `--colors` value: `none` (no colours) or a [`ColorCodec`] spelling.
pub fn parse_colors(text: &str) -> Result<ColorsArg, String> {
    if text == "none" {
        return Ok(ColorsArg(None));
    }
    ColorCodec::parse(text).map(|c| ColorsArg(Some(c)))
}

/// Parses a byte count: digits with an optional K, M, G or T suffix (powers of 1024).
pub fn parse_bytes(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let (digits, shift) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let shift = match c.to_ascii_uppercase() {
                'K' => 10,
                'M' => 20,
                'G' => 30,
                'T' => 40,
                _ => return Err(format!("unknown size suffix {c:?} (K, M, G or T)")),
            };
            (&t[..i], shift)
        }
        _ => (t, 0),
    };
    let n: u64 = digits
        .parse()
        .map_err(|e| format!("bad byte count {text:?}: {e}"))?;
    n.checked_mul(1u64 << shift)
        .filter(|&b| b > 0)
        .ok_or_else(|| format!("byte count {text:?} out of range (1..2^64)"))
}

/// `verify` found nothing wrong but could not prove the voxels (no content digest): the CLI
/// prints this line and exits 2.
#[derive(Debug)]
pub struct Unproven(pub String);

impl std::fmt::Display for Unproven {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Unproven {}

/// Parses "x,y,z".
pub fn parse_vec3(text: &str) -> Result<[f32; 3], String> {
    let parts: Vec<&str> = text.split(',').collect();
    if parts.len() != 3 {
        return Err(format!("expected x,y,z, got {text:?}"));
    }
    let mut v = [0f32; 3];
    for (out, part) in v.iter_mut().zip(parts) {
        *out = part
            .trim()
            .parse()
            .map_err(|e| format!("bad number {part:?}: {e}"))?;
        if !out.is_finite() {
            return Err(format!("{part:?} is not a finite number"));
        }
    }
    Ok(v)
}

/// Imports, voxelizes and builds the SVDAG of a scene; returns the DAG, the build report and
/// the digest of the source voxels (computed before the SVDAG is built).
pub fn build_scene_digest(
    args: &BuildArgs,
    quiet: bool,
) -> Result<(Svdag, BuildReport, VoxelDigest)> {
    let options = ImportOptions {
        resolution: args.resolution,
        vox_scale: args.vox_scale,
        texture_override: args.texture.clone(),
    };
    let bar = progress_bar(quiet);
    let start = Instant::now();
    let mut voxels = scene::import_in(&args.input, &options, args.asset_root.as_deref(), &bar)?;
    bar.finish_and_clear();
    if args.no_colors || args.colors.0.is_none() {
        voxels.colors = Vec::new();
    }
    let voxelize_time = start.elapsed();
    let digest = VoxelDigest::of_codes(&voxels.codes);
    let start = Instant::now();
    let dag = Svdag::from_voxels(&voxels)?;
    let build_time = start.elapsed();
    drop(voxels);
    let stats = dag.stats();
    let report = BuildReport {
        input: args.input.clone(),
        resolution: dag.resolution,
        voxels: stats.voxels,
        voxelize_s: voxelize_time.as_secs_f64(),
        build_s: build_time.as_secs_f64(),
        peak_rss_bytes: peak_rss_bytes(),
        stats,
    };
    Ok((dag, report, digest))
}

/// The transform set of a `--transforms` value (translations are reported separately).
fn transform_set(t: TransformsArg) -> TransformSet {
    match t {
        TransformsArg::None => TransformSet::None,
        TransformsArg::S => TransformSet::Mirrors,
        TransformsArg::A => TransformSet::AxisPermutations,
        TransformsArg::Sa | TransformsArg::Sat => TransformSet::All,
    }
}

/// The tsvdag modes `voxdag build` tries: the one pinned by `--tsvdag-mode` or
/// `--no-lut`/`--no-huffman`, else base, lut and huffman (the smallest is kept).
pub fn tsvdag_modes(args: &BuildArgs) -> Vec<TsvdagOptions> {
    let mode = |lut, huffman| TsvdagOptions { lut, huffman };
    match args.tsvdag_mode {
        Some(TsvdagModeArg::Base) => vec![mode(false, false)],
        Some(TsvdagModeArg::Lut) => vec![mode(true, false)],
        Some(TsvdagModeArg::Huffman) => vec![mode(true, true)],
        None if args.no_lut || args.no_huffman => vec![mode(!args.no_lut, !args.no_huffman)],
        None => TsvdagOptions::MODES.to_vec(),
    }
}

/// Encodes a DAG as `voxdag build` asks; tsvdag: builds the transform DAG (the translation
/// search of `--transforms sat` reports on a progress bar) and keeps the smallest of `modes`.
/// Takes the DAG by value: each stage (SVDAG, canonical DAG, transform DAG, graph) is dropped
/// as the next is made, so a 64K^3 scene holds one of them at a time.
pub fn encode_dag(
    dag: Svdag,
    encoding: EncodingArg,
    transforms: TransformsArg,
    modes: &[TsvdagOptions],
    quiet: bool,
) -> Result<EncodedDag> {
    Ok(match encoding {
        EncodingArg::Svdag32 => EncodedDag::Svdag32(dag),
        EncodingArg::Ssvdag => EncodedDag::Ssvdag(SsvdagEncoding::build(&dag)?),
        EncodingArg::Tsvdag => {
            let bar = progress_bar(quiet);
            bar.set_message("canonical");
            let canonical =
                CanonicalDag::build_with_progress(&dag, transform_set(transforms), &bar);
            drop(dag);
            bar.set_position(0);
            bar.set_message("translations");
            let tdag =
                TransformDag::from_canonical(canonical, transforms == TransformsArg::Sat, &bar);
            bar.finish_and_clear();
            let graph = TransformGraph::from_transform_dag(tdag);
            EncodedDag::Tsvdag(TsvdagEncoding::encode_smallest(graph, modes)?)
        }
    })
}

/// [`encode_dag`] with `voxdag build`'s encoding options, and the time it took.
fn encode_as_asked(dag: Svdag, args: &BuildArgs, quiet: bool) -> Result<(EncodedDag, Duration)> {
    let start = Instant::now();
    let encoded = encode_dag(
        dag,
        args.encoding,
        args.transforms,
        &tsvdag_modes(args),
        quiet,
    )?;
    Ok((encoded, start.elapsed()))
}

/// Loads a `.vdag` file of any encoding as an SVDAG with its decoded colours, decoding compact
/// encodings on the CPU.
pub fn load_svdag(path: &Path) -> Result<Svdag> {
    Ok(svdag_of(VdagFile::load(path)?, path)?.0)
}

/// [`load_svdag`] for renderers: a file that stores its colours chunked gives them encoded
/// (`Some`) and an SVDAG without colours (decoded per hit, never all at once). A material
/// scene's voxels come with their palette colours (`palette[id]`).
pub fn load_svdag_stored(path: &Path) -> Result<(Svdag, Option<StoredColors>)> {
    svdag_of(VdagFile::load_encoded_colors(path)?, path)
}

/// The SVDAG of a loaded file and its stored colours.
fn svdag_of(mut file: VdagFile, path: &Path) -> Result<(Svdag, Option<StoredColors>)> {
    expand_materials(&mut file);
    let kind = file.encoded.kind();
    if kind != voxdag::dag::encode::EncodingKind::Svdag32 {
        log::info!(
            "{}: decoding the {} encoding to svdag32 on the CPU",
            path.display(),
            kind.name()
        );
    }
    let stored_colors = file.stored_colors.take();
    Ok((file.into_svdag(path)?, stored_colors))
}

/// Gives a material scene's voxels their palette colours (what renderers show).
pub fn expand_materials(file: &mut VdagFile) {
    if let Some(m) = file.materials.take() {
        file.colors = m.to_colors();
    }
}

/// `voxdag build`: the streaming build, or the in-memory one with `--in-memory`.
pub fn build(args: &BuildArgs, quiet: bool) -> Result<()> {
    check_output(&args.output)?;
    if let Some(report) = &args.report {
        check_output(report)?;
    }
    if is_vdag(&args.input) {
        return transcode(args, quiet);
    }
    if let Some(part) = args.part {
        return crate::partition::build_part(args, part, quiet);
    }
    // `--materials` quantizes every colour at once (k-means), so it builds in memory.
    if !args.in_memory && args.materials.is_none() {
        return crate::stream::build_streaming(args, quiet);
    }
    let (dag, report, digest) = build_scene_digest(args, quiet)?;
    let (colors, stored_colors, materials) = match args.materials {
        Some(k) => (Vec::new(), None, Some(quantize_materials(&dag, k)?)),
        None => {
            let (colors, stored) = encode_colors(&dag, args, quiet)?;
            (colors, stored, None)
        }
    };
    let (encoded, encode_time) = encode_as_asked(dag, args, quiet)?;
    let summary = EncodedSummary::of(&encoded);
    let file = VdagFile {
        encoded,
        colors,
        digest: Some(digest),
        stored_colors,
        materials,
    };
    file.save(&args.output)?;
    let timing = format!(
        "voxelize {:.2} s, build {:.2} s",
        report.voxelize_s, report.build_s
    );
    summary.finish(args, &report, &timing, encode_time)
}

/// Whether `path` names a saved scene (`.vdag`) rather than a model to voxelize.
fn is_vdag(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vdag"))
}

/// `voxdag build SCENE.vdag`: re-encodes a saved scene (any encoding, decoded on the CPU) with
/// `--encoding` / `--transforms`, keeping its colours or materials as they are stored (the
/// voxels and their Morton order do not change); nothing is voxelized. This is how a scene
/// built once at a high resolution (a streamed 64K^3 svdag32) is compressed afterwards.
fn transcode(args: &BuildArgs, quiet: bool) -> Result<()> {
    if args.part.is_some() {
        bail!(
            "--part splits the build of a model; {} is already a built scene",
            args.input.display()
        );
    }
    if args.materials.is_some() {
        bail!(
            "--materials quantizes a model's colours when it is built; {} is already built",
            args.input.display()
        );
    }
    let start = Instant::now();
    // Chunked colours go to the new file as they are stored (the colour order is the same for
    // every node encoding): checked, never all decoded.
    let mut file = VdagFile::load_encoded_colors(&args.input)?;
    let materials = file.materials.take();
    let stored_colors = file.stored_colors.take();
    let mut digest = file.digest;
    let mut dag = file.into_svdag(&args.input)?;
    if let Some(r) = args.resolution.filter(|&r| r != dag.resolution) {
        bail!(
            "--resolution {r}: {} is a {}^3 scene (a built scene keeps its resolution)",
            args.input.display(),
            dag.resolution
        );
    }
    if digest.is_none() && args.encoding != EncodingArg::Svdag32 {
        // A scene saved without the voxel digest (an edited one: `voxdag edit -o`, or any
        // `Svdag::save`): the compact encodings store it for `verify`, so it is taken from the
        // voxels the file holds.
        digest = Some(voxel_digest(&dag)?);
    }
    let (colors, stored_colors) = if args.no_colors || args.colors.0.is_none() {
        (Vec::new(), None)
    } else {
        (std::mem::take(&mut dag.colors), stored_colors)
    };
    let load_time = start.elapsed();
    let stats = dag.stats();
    let (encoded, encode_time) = encode_as_asked(dag, args, quiet)?;
    let summary = EncodedSummary::of(&encoded);
    let file = VdagFile {
        encoded,
        colors,
        digest,
        stored_colors,
        materials,
    };
    file.save(&args.output)?;
    let report = BuildReport {
        input: args.input.clone(),
        resolution: stats.resolution,
        voxels: stats.voxels,
        voxelize_s: 0.0,
        build_s: load_time.as_secs_f64(),
        peak_rss_bytes: peak_rss_bytes(),
        stats,
    };
    let timing = format!("loaded and decoded in {}", seconds(load_time));
    summary.finish(args, &report, &timing, encode_time)
}

/// What a build's summary line says of its encoded DAG, taken before the DAG is moved into
/// its file.
pub struct EncodedSummary {
    bytes: u64,
    kind: String,
}

impl EncodedSummary {
    /// The byte size and encoding name (with the TSVDAG mode) of `encoded`.
    pub fn of(encoded: &EncodedDag) -> EncodedSummary {
        let kind = match encoded {
            EncodedDag::Tsvdag(e) => format!("tsvdag ({} mode)", e.options.mode_name()),
            other => other.kind().name().to_string(),
        };
        EncodedSummary {
            bytes: encoded.byte_size(),
            kind,
        }
    }

    /// Prints the build's one-line summary (`timing`: how the voxels were made, and in what
    /// time) and writes `--report`.
    pub fn finish(
        &self,
        args: &BuildArgs,
        report: &BuildReport,
        timing: &str,
        encode_time: Duration,
    ) -> Result<()> {
        println!(
            "{}: {}^3, {} voxels, {} SVDAG nodes, {} {} bytes ({timing}, encode {}, peak {:.0} MiB)",
            args.output.display(),
            report.resolution,
            report.voxels,
            report.stats.levels.iter().map(|l| l.svdag).sum::<u64>(),
            self.bytes,
            self.kind,
            seconds(encode_time),
            report.peak_rss_bytes as f64 / (1024.0 * 1024.0)
        );
        if let Some(path) = &args.report {
            write_json(path, report)?;
        }
        Ok(())
    }
}

/// `--materials K`: the DAG's colours quantized into a palette of at most `k` entries
/// (`docs/materials.md`); a scene without colours gets one white material.
pub(crate) fn quantize_materials(dag: &Svdag, k: u32) -> Result<Materials> {
    let start = Instant::now();
    let materials = if dag.colors.is_empty() {
        Materials::new(vec![0xffff_ffff], vec![0; dag.voxel_count() as usize])?
    } else {
        Materials::quantize(&dag.colors, k)?
    };
    let time = start.elapsed();
    let rmse = voxdag::attr::rmse(&dag.colors, &materials.to_colors());
    println!(
        "materials: {} voxels, palette of {} (at most {k} asked), 4-bit ids {} bytes, RMSE {:.4}, in {}",
        materials.ids.len(),
        materials.palette.len(),
        materials.ids.len().div_ceil(2),
        rmse,
        seconds(time)
    );
    Ok(materials)
}

/// Encodes the DAG's colours as `--colors` asks; returns the colours a reader will decode and
/// their stored form (`None`: no colours, or none asked for).
fn encode_colors(
    dag: &Svdag,
    args: &BuildArgs,
    quiet: bool,
) -> Result<(Vec<u32>, Option<StoredColors>)> {
    let Some(codec) = args.colors.0.filter(|_| !dag.colors.is_empty()) else {
        return Ok((Vec::new(), None));
    };
    let bar = progress_bar(quiet);
    let start = Instant::now();
    let stored = StoredColors::encode(dag, codec, args.chunk_depth, &bar)
        .with_context(|| format!("encoding colours with {}", codec.name()))?;
    bar.finish_and_clear();
    let decoded = stored.chunks.decode_all()?;
    println!(
        "colours: {} {} -> {} bytes ({:.1}% of RGB888) in {} chunks at depth {}, RMSE {:.4}, encoded in {}",
        dag.colors.len(),
        codec.name(),
        stored.chunks.byte_size(),
        100.0 * stored.chunks.byte_size() as f64 / (3.0 * dag.colors.len() as f64),
        stored.chunks.chunk_count(),
        stored.chunks.chunk_depth,
        stored.rmse,
        seconds(start.elapsed())
    );
    Ok((decoded, Some(stored)))
}

/// Colour storage of a file: stored bytes, raw RGB888 bytes (3 per colour) and the RMSE measured
/// at encode time (0 for uncompressed colours).
#[derive(Clone, Debug, Serialize)]
pub struct ColorStats {
    /// Encoder name (`raw` for a file with uncompressed RGBA8 colours, `none` without colours).
    pub codec: String,
    /// Colours stored.
    pub colors: u64,
    /// Bytes of the stored colours (words and chunk tables; 4 per colour for RGBA8 files).
    pub color_bytes: u64,
    /// 3 bytes per colour (RGB888).
    pub raw_color_bytes: u64,
    /// RMSE of the stored colours against the voxelizer's, RGB in [0, 1].
    pub color_rmse: f64,
    /// Chunks (0 for RGBA8 files).
    pub chunks: u64,
}

impl ColorStats {
    /// The statistics of a file's colours: `stored`, or `raw_colors` RGBA8 words when `None`.
    pub fn new(raw_colors: u64, stored: Option<&StoredColors>) -> ColorStats {
        match stored {
            Some(s) => ColorStats {
                codec: s.chunks.codec.name(),
                colors: s.chunks.color_count(),
                color_bytes: s.chunks.byte_size(),
                raw_color_bytes: 3 * s.chunks.color_count(),
                color_rmse: s.rmse,
                chunks: s.chunks.chunk_count() as u64,
            },
            None => ColorStats {
                codec: if raw_colors == 0 { "none" } else { "raw" }.into(),
                colors: raw_colors,
                color_bytes: 4 * raw_colors,
                raw_color_bytes: 3 * raw_colors,
                color_rmse: 0.0,
                chunks: 0,
            },
        }
    }
}

/// `voxdag stats`.
pub fn stats(args: &StatsArgs, quiet: bool) -> Result<()> {
    // Statistics need the colours' count and storage only: chunks stay encoded.
    let mut file = VdagFile::load_encoded_colors(&args.file)?;
    let encoding = file.encoded.kind().name();
    let mode = match &file.encoded {
        EncodedDag::Tsvdag(e) => Some(e.options.mode_name()),
        _ => None,
    };
    let stored = file.stored_colors.take();
    // Palette size, ids and their bytes of a material scene.
    let materials = file.materials.take().map(|m| {
        let (palette, ids) = (m.palette.len() as u64, m.ids.len() as u64);
        (palette, ids, 80 + ids.div_ceil(2))
    });
    let dag = file.into_svdag(&args.file)?;
    let colors = ColorStats::new(dag.colors.len() as u64, stored.as_ref());
    let (stats, bytes) = if args.quick {
        (dag.stats(), Vec::new())
    } else {
        describe(&dag, quiet)?
    };
    if args.json {
        let mut json = stats_json(&stats, &bytes, &colors)?;
        if let Some(obj) = json.as_object_mut() {
            obj.insert("encoding".into(), encoding.into());
            obj.insert("tsvdag_mode".into(), mode.into());
            if let Some((palette, ids, bytes)) = materials {
                let m = serde_json::json!({ "palette": palette, "ids": ids, "bytes": bytes });
                obj.insert("materials".into(), m);
            }
        }
        println!("{}", serde_json::to_string(&json)?);
    } else {
        let mode = mode.map_or_else(String::new, |m| format!(" ({m} mode)"));
        print!("{}", stats_table(&args.file, &stats, &bytes));
        println!("  stored      {encoding}{mode}");
        print!("{}", color_line(&colors));
        if let Some((palette, ids, bytes)) = materials {
            println!("  materials   {ids} 4-bit ids, {palette}-entry palette: {bytes} bytes");
        }
    }
    Ok(())
}

/// Statistics with the transform counts and the bytes of every encoding (runs each search once).
fn describe(dag: &Svdag, quiet: bool) -> Result<(DagStats, Vec<(String, u64)>)> {
    let bar = progress_bar(quiet);
    bar.set_message("translations");
    let analysis = analyze_symmetry(dag, &bar);
    bar.finish_and_clear();
    let stats = dag.stats().with_symmetry(&analysis.counts);
    Ok((stats, encoded_bytes(dag, analysis)?))
}

/// The colour line of the stats table.
fn color_line(c: &ColorStats) -> String {
    if c.colors == 0 {
        return "  colours     none\n".into();
    }
    format!(
        "  colours     {} {}: {} bytes ({:.1}% of RGB888 {}), {} chunks, RMSE {:.4}\n",
        c.colors,
        c.codec,
        c.color_bytes,
        100.0 * c.color_bytes as f64 / c.raw_color_bytes as f64,
        c.raw_color_bytes,
        c.chunks,
        c.color_rmse
    )
}

/// The `stats --json` document: [`DagStats`] with the encoded sizes added under `bytes` and the
/// colour fields of [`ColorStats`] at the top level.
fn stats_json(
    stats: &DagStats,
    bytes: &[(String, u64)],
    colors: &ColorStats,
) -> Result<serde_json::Value> {
    let mut value = serde_json::to_value(stats)?;
    if let (Some(obj), serde_json::Value::Object(c)) =
        (value.as_object_mut(), serde_json::to_value(colors)?)
    {
        obj.insert("color_codec".into(), c["codec"].clone());
        for key in ["color_bytes", "raw_color_bytes", "color_rmse"] {
            obj.insert(key.into(), c[key].clone());
        }
        obj.insert("color_chunks".into(), c["chunks"].clone());
    }
    if let Some(b) = value.get_mut("bytes").and_then(|b| b.as_object_mut()) {
        for (name, v) in bytes {
            b.insert(name.clone(), serde_json::Value::from(*v));
        }
    }
    Ok(value)
}

/// Bytes of the DAG in each encoding: `ssvdag`, `tsvdag` (S+A+T, tables, Huffman) and the
/// ablations `tsvdag_base` (neither) and `tsvdag_lut` (tables only).
pub fn encoded_bytes(dag: &Svdag, analysis: SymmetryAnalysis) -> Result<Vec<(String, u64)>> {
    let graph = voxdag::dag::encode::TransformGraph::from_transform_dag(analysis.sat);
    let mut out = vec![(
        "ssvdag".to_string(),
        SsvdagEncoding::encode(&analysis.ssvdag, dag.resolution)?.byte_size(),
    )];
    for (name, lut, huffman) in [
        ("tsvdag", true, true),
        ("tsvdag_base", false, false),
        ("tsvdag_lut", true, false),
    ] {
        let e = TsvdagEncoding::encode(&graph, TsvdagOptions { lut, huffman })?;
        out.push((name.to_string(), e.byte_size()));
    }
    Ok(out)
}

/// Most voxels `verify` enumerates to check a file that has only the v1 position checksum.
const LEGACY_MAX_VOXELS: u64 = 1 << 32;

/// `voxdag verify`: decodes the stored nodes and colours and compares them with the content
/// digest written with the file (O(stored nodes) for svdag32 and ssvdag); `--against` also
/// compares voxels and colours (or materials) with another file, naming the first difference. A file without a
/// content digest is checked as far as it can be and reported [`Unproven`] (exit 2).
pub fn verify(args: &VerifyArgs) -> Result<()> {
    // Chunked colours are hashed a batch of chunks at a time, never all decoded at once
    // (sponza-crytek at 32768: 40 GB decoded), here and in `--against`.
    let (file, stored) = VdagFile::load_encoded_colors_with_digest(&args.file)?;
    let name = args.file.display();
    let kind = file.encoded.kind().name();
    if let EncodedDag::Svdag32(dag) = &file.encoded {
        dag.validate()?;
    }
    let mut digest = ContentDigest::of(&file.encoded, &file.colors)
        .with_context(|| format!("{name}: traversing the {kind} encoding"))?;
    digest.colors = file
        .attributes_hash()
        .with_context(|| format!("{name}: decoding the colour chunks"))?;
    if let Some(m) = file.materials.as_ref() {
        if m.ids.len() as u64 != digest.voxels {
            bail!(
                "{name}: {} material ids for {} decoded voxels",
                m.ids.len(),
                digest.voxels
            );
        }
    }
    let colors = file.color_count();
    if colors != 0 && colors != digest.voxels {
        bail!(
            "{name}: {colors} colours for {} decoded voxels",
            digest.voxels
        );
    }
    if let Some(v1) = file.digest {
        if v1.voxels != digest.voxels {
            bail!(
                "{name}: decoded {} voxels, built from {} voxels",
                digest.voxels,
                v1.voxels
            );
        }
    }
    let unproven = match stored {
        Some(s) if s.voxels != digest.voxels || s.dag != digest.dag => bail!(
            "{name}: the decoded voxels ({} voxels, digest {}) differ from those it was \
             written with ({} voxels, digest {})",
            digest.voxels,
            hex128(digest.dag),
            s.voxels,
            hex128(s.dag)
        ),
        Some(s) if s.colors != digest.colors => bail!(
            "{name}: the decoded colours (hash {:016x}) differ from those it was written with \
             (hash {:016x})",
            digest.colors,
            s.colors
        ),
        Some(_) => None,
        None => Some(legacy_check(&file, &name.to_string(), digest.voxels)?),
    };
    let against = match &args.against {
        Some(other) => format!(
            "; the same voxels and {} as {}",
            compare_against(&file, &digest, &args.file, other)?,
            other.display()
        ),
        None => String::new(),
    };
    if let Some(what) = unproven {
        return Err(Unproven(format!(
            "no digest: the voxels are not proven ({name}: {what})"
        ))
        .into());
    }
    // Every colour chunk was decoded (by the load or by the hash); say what was checked.
    let colors = match &file.stored_colors {
        Some(s) => format!(
            ", {} colours in {} {} chunks decoded",
            s.chunks.color_count(),
            s.chunks.chunk_count(),
            s.chunks.codec.name()
        ),
        None => match &file.materials {
            Some(m) => format!(
                ", {} material ids of a {}-entry palette",
                m.ids.len(),
                m.palette.len()
            ),
            None if file.colors.is_empty() => String::new(),
            None => format!(", {} colours", file.colors.len()),
        },
    };
    println!(
        "ok: {name} ({kind}, {} voxels, digest {}{colors}, matching the content digest{against})",
        digest.voxels,
        hex128(digest.dag)
    );
    Ok(())
}

/// A 128-bit hash in hex.
fn hex128(h: [u64; 2]) -> String {
    format!("{:016x}{:016x}", h[1], h[0])
}

/// What `verify` can still check in a file without a content digest: the v1 position checksum
/// (section 4) when there is one and the voxels are few enough to enumerate. Returns what was
/// checked, for the "not proven" line.
fn legacy_check(file: &VdagFile, name: &str, voxels: u64) -> Result<String> {
    let Some(v1) = file.digest else {
        return Ok("structure and decoding checked; no digest stored".into());
    };
    if voxels > LEGACY_MAX_VOXELS {
        return Ok(format!(
            "structure checked; {voxels} voxels are too many to enumerate against the v1 \
             position checksum"
        ));
    }
    let d = file.encoded.digest()?;
    if d != v1 {
        bail!(
            "{name}: decoded {} voxels with checksum {:#010x}, built from {} voxels with \
             checksum {:#010x}",
            d.voxels,
            d.crc32,
            v1.voxels,
            v1.crc32
        );
    }
    Ok(format!(
        "voxel positions match the v1 checksum {:#010x}; no content digest covers the colours \
         and the DAG",
        d.crc32
    ))
}

/// `verify --against`: `file` (whose content digest is `digest`) holds the same voxels and the
/// same colours or materials as `other`. Equal digests prove it; where they differ, the first
/// differing voxel, colour or material id is named. Neither file's colours are decoded at once.
/// Returns what was compared besides the voxels ("colours", "materials" or "no colours").
fn compare_against(
    file: &VdagFile,
    digest: &ContentDigest,
    path: &Path,
    other: &Path,
) -> Result<&'static str> {
    let reference = VdagFile::load_encoded_colors(other)?;
    let theirs = ContentDigest::of(&reference.encoded, &[])?;
    if (digest.voxels, digest.dag) != (theirs.voxels, theirs.dag) {
        first_differing_voxel(file, path, &reference, other)?;
    }
    let attributes = |f: &VdagFile| match (&f.materials, f.color_count()) {
        (Some(_), _) => "materials",
        (None, 0) => "no colours",
        (None, _) => "colours",
    };
    let (ours, kind) = (attributes(file), attributes(&reference));
    if ours != kind {
        bail!(
            "same voxels, but {} has {ours} and {} has {kind}",
            path.display(),
            other.display()
        );
    }
    let theirs = reference
        .attributes_hash()
        .with_context(|| format!("{}: decoding the colour chunks", other.display()))?;
    if ours == "no colours" || theirs == digest.colors {
        return Ok(ours);
    }
    let voxel = |index: u64| -> Result<String> {
        let code = file.encoded.voxels().nth(index as usize).transpose()?;
        let [x, y, z] = voxdag::scene::morton::decode(code.unwrap_or_default());
        Ok(format!("voxel {index} ({x}, {y}, {z})"))
    };
    if let (Some(a), Some(b)) = (&file.materials, &reference.materials) {
        if a.palette != b.palette {
            bail!(
                "same voxels, different palettes: {:08x?} in {}, {:08x?} in {}",
                a.palette,
                path.display(),
                b.palette,
                other.display()
            );
        }
        if let Some(i) = a.ids.iter().zip(&b.ids).position(|(x, y)| x != y) {
            bail!(
                "first differing material: {}: id {} in {}, {} in {}",
                voxel(i as u64)?,
                a.ids[i],
                path.display(),
                b.ids[i],
                other.display()
            );
        }
    }
    let (mut x, mut y) = (ColorCursor::new(file), ColorCursor::new(&reference));
    let mut index = 0u64;
    while let (Some(a), Some(b)) = (x.next()?, y.next()?) {
        if a != b {
            bail!(
                "first differing colour: {}: {a:08x} in {}, {b:08x} in {}",
                voxel(index)?,
                path.display(),
                other.display()
            );
        }
        index += 1;
    }
    bail!("the attribute hashes differ, but every decoded colour and id is equal")
}

/// The decoded colours of a file in order: its raw colours, or its chunks decoded one at a time.
struct ColorCursor<'a> {
    /// The chunks still to decode (`None`: the raw colours are all in `buffer`).
    chunks: Option<(&'a ChunkedColors, usize)>,
    buffer: std::borrow::Cow<'a, [u32]>,
    at: usize,
}

impl<'a> ColorCursor<'a> {
    fn new(file: &'a VdagFile) -> ColorCursor<'a> {
        ColorCursor {
            chunks: file.encoded_only_colors().map(|c| (c, 0)),
            buffer: std::borrow::Cow::Borrowed(&file.colors),
            at: 0,
        }
    }

    /// The next colour (`None` after the last).
    fn next(&mut self) -> Result<Option<u32>> {
        while self.at == self.buffer.len() {
            match &mut self.chunks {
                Some((chunks, next)) if *next < chunks.chunk_count() => {
                    self.buffer = chunks.decode_chunk(*next)?.into();
                    *next += 1;
                    self.at = 0;
                }
                _ => return Ok(None),
            }
        }
        self.at += 1;
        Ok(Some(self.buffer[self.at - 1]))
    }
}

/// The first voxel where two files differ, as an error (enumerating both; `Ok` when none does).
fn first_differing_voxel(
    file: &VdagFile,
    path: &Path,
    reference: &VdagFile,
    other: &Path,
) -> Result<()> {
    let mut x_it = file.encoded.voxels();
    let mut y_it = reference.encoded.voxels();
    loop {
        match (x_it.next().transpose()?, y_it.next().transpose()?) {
            (None, None) => return Ok(()),
            (x, y) if x == y => continue,
            (x, y) => {
                let code = match (x, y) {
                    (Some(x), Some(y)) => x.min(y),
                    (Some(x), None) => x,
                    (None, Some(y)) => y,
                    (None, None) => unreachable!(),
                };
                let [vx, vy, vz] = voxdag::scene::morton::decode(code);
                let here = file.encoded.contains(vx, vy, vz)?;
                bail!(
                    "first differing voxel ({vx}, {vy}, {vz}): {} in {}, {} in {}",
                    if here { "set" } else { "empty" },
                    path.display(),
                    if here { "empty" } else { "set" },
                    other.display()
                );
            }
        }
    }
}

/// A human-readable table of DAG statistics (with the transform columns when computed).
pub fn stats_table(file: &Path, stats: &DagStats, encoded: &[(String, u64)]) -> String {
    let symmetry = stats.levels.iter().any(|l| l.sa.is_some());
    let mut out = format!(
        "{}\n  resolution  {}^3\n  voxels      {}\n  bytes       svo {}  svdag32 {}\n  level  node size        svo      svdag",
        file.display(),
        stats.resolution,
        stats.voxels,
        stats.bytes.svo,
        stats.bytes.svdag32
    );
    if symmetry {
        out += "     ssvdag          s          a         sa        sat";
    }
    out += "\n";
    let cell = |v: Option<u64>| v.map_or_else(|| "-".to_string(), |v| v.to_string());
    for level in &stats.levels {
        let size = 4u64 << level.level;
        out += &format!(
            "  {:>5}  {:>9} {:>10} {:>10}",
            level.level,
            format!("{size}^3"),
            level.svo,
            level.svdag
        );
        if symmetry {
            out += &format!(
                " {:>10} {:>10} {:>10} {:>10} {:>10}",
                cell(level.ssvdag),
                cell(level.s),
                cell(level.a),
                cell(level.sa),
                cell(level.sat)
            );
        }
        out += "\n";
    }
    if !encoded.is_empty() {
        let line: Vec<String> = encoded.iter().map(|(n, v)| format!("{n} {v}")).collect();
        out += &format!("  encoded     {}\n", line.join("  "));
    }
    out
}

/// `voxdag export-voxels`.
/// Exports know their size in advance: it is checked against `--max-output` and the free
/// space of the target filesystem before anything is written.
pub fn export_voxels(args: &ExportArgs) -> Result<()> {
    check_output(&args.output)?;
    let dag = load_svdag(&args.file)?;
    let voxels = dag.voxel_count();
    let size = match args.format {
        ExportFormat::XyzU32 => voxels.saturating_mul(12),
        // Header, size and voxel chunks, the 256-entry palette.
        ExportFormat::Vox => voxels.saturating_mul(4).saturating_add(2048),
    };
    if let Some(max) = args.max_output {
        if size > max {
            bail!(
                "{}: the export is {} ({voxels} voxels), more than --max-output {}",
                args.output.display(),
                voxdag::safety::human_bytes(size),
                voxdag::safety::human_bytes(max)
            );
        }
    }
    if let Some(free) = free_space(&args.output) {
        if size > free {
            bail!(
                "{}: the export is {} ({voxels} voxels), more than the {} free on its \
                 filesystem",
                args.output.display(),
                voxdag::safety::human_bytes(size),
                voxdag::safety::human_bytes(free)
            );
        }
    }
    match args.format {
        ExportFormat::XyzU32 => export_xyz_u32_file(&dag, &args.output)?,
        ExportFormat::Vox => export_vox(&dag, &args.output)?,
    }
    let line = format!("{}: wrote {voxels} voxels", args.output.display());
    if args.output.as_os_str() == "-" {
        eprintln!("{line}"); // stdout carries the export
    } else {
        println!("{line}");
    }
    Ok(())
}

/// Free bytes for an unprivileged user on the filesystem a new file at `output` goes to;
/// `None` for stdout and existing non-regular files (written in place) or when unknown.
fn free_space(output: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    if output.as_os_str() == "-"
        || std::fs::metadata(output).is_ok_and(|m| !m.is_file())
        || output.starts_with("/dev")
    {
        return None;
    }
    let dir = output
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    // SAFETY: `stat` is a plain struct statvfs fills in; `c` is a valid C string.
    let mut stat: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut stat) } != 0 {
        return None;
    }
    // The old file, when replaced, frees its blocks only after the rename.
    Some((stat.f_bavail as u64).saturating_mul(stat.f_frsize as u64))
}

/// Builds render settings from the CLI camera flags; the default camera frames `bounds` (the
/// occupied coarse nodes) or, for an empty scene, the whole grid of side `resolution`.
pub fn render_settings(
    args: &RenderArgs,
    bounds: Option<([u32; 3], [u32; 3])>,
    resolution: u32,
) -> RenderSettings {
    let mut camera = match bounds {
        Some((min, max)) => Camera::orbit(min.map(|v| v as f32), max.map(|v| v as f32)),
        None => Camera::orbit_default(resolution),
    };
    if let Some(eye) = args.eye {
        camera.eye = eye;
    }
    if let Some(target) = args.target {
        camera.target = target;
    }
    if let Some(fov) = args.fov {
        camera.fov_y_deg = fov;
    }
    let mut settings = RenderSettings::new(args.size.0, args.size.1, camera);
    settings.shadows = !args.no_shadows;
    settings
}

/// `voxdag render`: the GPU traverses the file's encoding as it is (svdag32, SSVDAG or TSVDAG
/// in any mode); `--cpu` decodes compact encodings to svdag32 for the CPU reference. `--pt`
/// path traces instead of the raster shading, on the same data (`crate::pathtrace`).
pub fn render(args: &RenderArgs) -> Result<()> {
    if let Some(fov) = args.fov {
        if !(1.0..=179.0).contains(&fov) {
            bail!("--fov {fov} out of range (1..=179 degrees)");
        }
    }
    check_output(&args.out)?;
    if let Some(trace) = &args.trace {
        check_output(trace)?;
    }
    if args.pt.pt {
        crate::pathtrace::check(&args.pt, &args.out)?;
    }
    if args.hash_dag || args.hash_table.is_some() {
        return crate::hash_render::render(args);
    }
    let start;
    let image = if args.cpu {
        let (dag, stored) = load_svdag_stored(&args.file)?;
        // Encoded colours are decoded per hit from their chunks, as an engine would keep them.
        let colors = match &stored {
            Some(s) => ColorSource::Chunked(&s.chunks),
            None => ColorSource::Raw(&dag.colors),
        };
        let settings = render_settings(args, dag.occupied_bounds(), dag.resolution);
        if args.pt.pt {
            return crate::pathtrace::render_cpu(&args.pt, &dag, colors, settings, &args.out);
        }
        start = Instant::now();
        let index = VoxelIndex::new(&dag);
        render_cpu_with(&dag, &index, colors, &settings)?
    } else {
        // The GPU decodes chunked colours per hit: they stay encoded in memory too.
        let mut file = VdagFile::load_encoded_colors(&args.file)?;
        expand_materials(&mut file);
        let stored = file.stored_colors.take();
        let colors = match &stored {
            Some(s) => ColorSource::Chunked(&s.chunks),
            None => ColorSource::Raw(&file.colors),
        };
        let bounds = file.encoded.occupied_bounds()?;
        let settings = render_settings(args, bounds, file.encoded.resolution());
        let (profile, trace) = (args.profile, args.trace.as_deref());
        if args.pt.pt {
            let out = &args.out;
            let encoded = &file.encoded;
            return crate::pathtrace::render_gpu(
                &args.pt, encoded, colors, settings, profile, trace, out,
            );
        }
        start = Instant::now();
        let context = GpuContext::new(&GpuOptions::default())?;
        let image = render_gpu(&context, &file.encoded, colors, &settings, profile, trace)?;
        drop(context);
        image
    };
    image.save_png(&args.out)?;
    println!(
        "{}: {}x{} in {}",
        args.out.display(),
        args.size.0,
        args.size.1,
        seconds(start.elapsed())
    );
    Ok(())
}

/// Renders on the GPU, printing the profile table and writing the trace when asked.
fn render_gpu(
    context: &Arc<GpuContext>,
    dag: &EncodedDag,
    colors: ColorSource,
    settings: &RenderSettings,
    print_profile: bool,
    trace: Option<&Path>,
) -> Result<voxdag::render::RenderOutput> {
    let renderer = GpuRenderer::new(context)?;
    let mut profiler = Profiler::new(context)?;
    let scene = profiler.cpu_span("upload", || renderer.upload_encoded(dag, colors))?;
    let image = renderer.render(&scene, settings, Some(&mut profiler))?;
    if print_profile {
        print!("{}", profiler.table());
    }
    if let Some(path) = trace {
        profiler.write_chrome_trace(path)?;
        println!(
            "{}: Chrome trace written (open in Perfetto)",
            path.display()
        );
    }
    Ok(image)
}

/// `voxdag demo`: the README's quick start.
pub fn demo(args: &DemoArgs, quiet: bool) -> Result<()> {
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/avocado/Avocado.gltf");
    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("creating {}", args.out_dir.display()))?;
    let vdag = args.out_dir.join("avocado.vdag");
    let build_args = BuildArgs {
        input,
        resolution: Some(args.resolution),
        vox_scale: 1,
        texture: None,
        asset_root: None,
        no_colors: false,
        colors: ColorsArg(Some(ColorCodec::Lossless(LosslessVariant::Rgb888))),
        materials: None,
        chunk_depth: None,
        output: vdag.clone(),
        report: Some(args.out_dir.join("avocado-build.json")),
        encoding: EncodingArg::Svdag32,
        transforms: TransformsArg::Sa,
        tsvdag_mode: None,
        no_lut: false,
        no_huffman: false,
        memory_budget: None,
        in_memory: false,
        part: None,
    };
    build(&build_args, quiet)?;
    let render_args = RenderArgs {
        file: vdag.clone(),
        size: (1024, 768),
        out: args.out_dir.join("avocado.png"),
        eye: None,
        target: None,
        fov: None,
        no_shadows: false,
        cpu: false,
        hash_dag: false,
        hash_table: None,
        profile: true,
        trace: Some(args.out_dir.join("avocado-trace.json")),
        pt: Default::default(),
    };
    render(&render_args)?;
    let (dag, stored) = load_svdag_stored(&vdag)?;
    let colors = ColorStats::new(dag.colors.len() as u64, stored.as_ref());
    let (stats, bytes) = describe(&dag, quiet)?;
    print!("{}", stats_table(&vdag, &stats, &bytes));
    print!("{}", color_line(&colors));
    write_json(
        &args.out_dir.join("avocado-stats.json"),
        &stats_json(&stats, &bytes, &colors)?,
    )?;
    Ok(())
}

/// Fails early, before any work, when an output cannot be written (missing or unwritable
/// folder, a directory in its place).
pub fn check_output(output: &Path) -> Result<()> {
    Ok(check_output_path(output)?)
}

/// Reads a JSON file, naming it in errors.
pub fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let json = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_slice(&json).with_context(|| format!("parsing {}", path.display()))
}

/// Writes pretty JSON atomically.
pub fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    write_atomic(path, |w| Ok(serde_json::to_writer_pretty(w, value)?))
        .with_context(|| format!("writing {}", path.display()))
}

/// "1.23 s" or "45.6 ms".
pub fn seconds(d: Duration) -> String {
    if d.as_secs_f64() >= 1.0 {
        format!("{:.2} s", d.as_secs_f64())
    } else {
        format!("{:.1} ms", d.as_secs_f64() * 1e3)
    }
}
