//! `voxdag bench render --formats ...`: GPU time per frame of each DAG format, traversed
//! directly, relative to svdag32 in the same run (issue 14 targets on lavapipe: TSVDAG S+A
//! full encoding <= +15%, S+A+T <= +30%).

use std::time::Instant;

use anyhow::{bail, Result};
use serde::Serialize;
use voxdag::dag::encode::{EncodedDag, SsvdagEncoding, TsvdagEncoding, TsvdagOptions};
use voxdag::dag::transform::TransformSet;
use voxdag::dag::Svdag;
use voxdag::gpu::{GpuContext, Profiler};
use voxdag::render::cpu::ColorSource;
use voxdag::render::gpu::{GpuRenderer, GpuScene};
use voxdag::render::RenderSettings;

/// One format's row.
#[derive(Serialize)]
pub struct FormatBench {
    /// `svdag32`, `ssvdag`, `tsvdag-sa-base`, ... `tsvdag-sat-huffman`.
    pub format: String,
    /// Bytes of the encoded nodes (payload).
    pub node_bytes: u64,
    /// GPU bytes of the node data as uploaded (words, voxel counts, info block).
    pub gpu_dag_bytes: u64,
    /// Seconds to encode (0 for svdag32).
    pub encode_s: f64,
    /// Median GPU time of the primary-ray pass over the frames, ms.
    pub frame_ms: f64,
    /// Every frame's GPU time, ms.
    pub frames_ms: Vec<f64>,
    /// `frame_ms` relative to svdag32 in the same run (1.0 = same).
    pub vs_svdag32: f64,
    /// Pixels whose first hit differs from svdag32's (must be 0).
    pub first_hit_mismatches: usize,
}

/// The format names `--formats` accepts.
pub const FORMAT_NAMES: [&str; 8] = [
    "ssvdag",
    "tsvdag-sa-base",
    "tsvdag-sa-lut",
    "tsvdag-sa-huffman",
    "tsvdag-sat-base",
    "tsvdag-sat-lut",
    "tsvdag-sat-huffman",
    "svdag32",
];

/// `dag` encoded as format `name` (one of [`FORMAT_NAMES`]).
pub fn encode(dag: &Svdag, name: &str) -> Result<EncodedDag> {
    let mode = |m: &str| match m {
        "base" => Some(TsvdagOptions {
            lut: false,
            huffman: false,
        }),
        "lut" => Some(TsvdagOptions {
            lut: true,
            huffman: false,
        }),
        "huffman" => Some(TsvdagOptions {
            lut: true,
            huffman: true,
        }),
        _ => None,
    };
    Ok(match name.split('-').collect::<Vec<_>>().as_slice() {
        ["svdag32"] => EncodedDag::Svdag32(dag.clone()),
        ["ssvdag"] => EncodedDag::Ssvdag(SsvdagEncoding::build(dag)?),
        ["tsvdag", set @ ("sa" | "sat"), m] if mode(m).is_some() => {
            EncodedDag::Tsvdag(TsvdagEncoding::build_with_translations(
                dag,
                TransformSet::All,
                *set == "sat",
                mode(m).expect("checked"),
            )?)
        }
        _ => bail!(
            "unknown format '{name}' in --formats (known: {})",
            FORMAT_NAMES.join(", ")
        ),
    })
}

/// Median GPU ms of `frames` renders of `scene`, each frame's ms, and the first hits.
fn time_frames(
    context: &std::sync::Arc<GpuContext>,
    renderer: &GpuRenderer,
    scene: &GpuScene,
    settings: &RenderSettings,
    frames: u32,
) -> Result<(f64, Vec<f64>, Vec<voxdag::render::FirstHit>)> {
    // Warm-up (pipeline compilation, first touch of memory), which also gives the first hits.
    let (_, hits) = renderer.render_first_hits(scene, settings)?;
    let mut times = Vec::new();
    for _ in 0..frames {
        let mut profiler = Profiler::new(context)?;
        renderer.render(scene, settings, Some(&mut profiler))?;
        times.push(
            profiler
                .passes()
                .iter()
                .filter(|p| p.name == "primary rays")
                .map(|p| p.gpu_ms)
                .sum(),
        );
    }
    Ok((super::median(&times), times, hits))
}

/// Times every format of `names` (svdag32 first, always) on `dag` with `settings`.
pub fn bench_formats(
    context: &std::sync::Arc<GpuContext>,
    dag: &Svdag,
    names: &[String],
    settings: &RenderSettings,
    frames: u32,
) -> Result<Vec<FormatBench>> {
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    let renderer = GpuRenderer::new(context)?;
    let mut rows: Vec<FormatBench> = Vec::new();
    let mut order = vec!["svdag32".to_string()];
    order.extend(names.iter().filter(|n| *n != "svdag32").cloned());
    let mut reference: Option<(f64, Vec<voxdag::render::FirstHit>)> = None;
    for name in &order {
        let start = Instant::now();
        let encoded = encode(dag, name)?;
        let encode_s = if name == "svdag32" {
            0.0
        } else {
            start.elapsed().as_secs_f64()
        };
        let scene = renderer.upload_encoded(&encoded, ColorSource::Raw(&dag.colors))?;
        let (ms, frames_ms, hits) = time_frames(context, &renderer, &scene, settings, frames)?;
        let (base_ms, mismatches) = match &reference {
            None => (ms, 0),
            Some((base, ref_hits)) => (
                *base,
                hits.iter().zip(ref_hits).filter(|(a, b)| a != b).count(),
            ),
        };
        eprintln!(
            "{name}: {ms:.1} ms per frame ({:+.1}% vs svdag32), {mismatches} first-hit mismatches",
            (ms / base_ms - 1.0) * 100.0
        );
        rows.push(FormatBench {
            format: name.clone(),
            node_bytes: encoded.byte_size(),
            gpu_dag_bytes: scene.dag_bytes(),
            encode_s,
            frame_ms: ms,
            frames_ms,
            vs_svdag32: ms / base_ms,
            first_hit_mismatches: mismatches,
        });
        if reference.is_none() {
            reference = Some((ms, hits));
        }
    }
    Ok(rows)
}

/// The Markdown table of the rows.
pub fn markdown(rows: &[FormatBench], frames: u32) -> String {
    let mut md = format!(
        "\n| format | node bytes | GPU DAG bytes | encode s | GPU ms/frame (median of {frames}) | vs svdag32 | first-hit mismatches |\n|---|---|---|---|---|---|---|\n"
    );
    for r in rows {
        md.push_str(&format!(
            "| {} | {} | {} | {:.1} | {:.1} | {:+.1}% | {} |\n",
            r.format,
            r.node_bytes,
            r.gpu_dag_bytes,
            r.encode_s,
            r.frame_ms,
            (r.vs_svdag32 - 1.0) * 100.0,
            r.first_hit_mismatches
        ));
    }
    md
}
