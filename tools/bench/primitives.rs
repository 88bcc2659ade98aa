//! `voxdag bench primitives`: throughput of the GPU primitives (exclusive scan, compaction,
//! radix sort with 4- and 8-bit digits) against their CPU references in the same run. GPU time
//! is the sum of the profiled passes; every result is checked exactly (a mismatch fails).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use serde::Serialize;
use voxdag::compute::{reference, PrimitiveOptions, Primitives};
use voxdag::gpu::{GpuContext, GpuOptions, Profiler};

use super::write_outputs;

/// Arguments of `voxdag bench primitives`.
#[derive(Args)]
pub struct BenchPrimitivesArgs {
    /// Elements per primitive, as a power of two.
    #[arg(long, default_value_t = 22, value_parser = clap::value_parser!(u32).range(1..=26))]
    log2: u32,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-primitives.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-primitives.md")]
    markdown: PathBuf,
}

impl BenchPrimitivesArgs {
    /// The output files, checked before the work starts.
    pub(super) fn outputs(&self) -> Vec<&std::path::Path> {
        vec![self.json.as_path(), self.markdown.as_path()]
    }
}

/// One primitive at one size.
#[derive(Serialize)]
struct PrimitiveRow {
    primitive: String,
    elements: u64,
    gpu_ms: f64,
    gpu_melem_s: f64,
    cpu_ms: f64,
    cpu_melem_s: f64,
    gpu_over_cpu: f64,
}

/// The whole run.
#[derive(Serialize)]
struct PrimitivesReport {
    device: String,
    subgroup_size: u32,
    rows: Vec<PrimitiveRow>,
    /// Per-pass GPU table of the profiler (where the time goes).
    passes: String,
}

/// splitmix64, for reproducible inputs.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Runs the benchmark.
pub fn bench_primitives(args: &BenchPrimitivesArgs) -> Result<()> {
    let ctx = GpuContext::new(&GpuOptions::default())?;
    let n = 1usize << args.log2;
    let mut state = 8u64;
    let keys64: Vec<u64> = (0..n).map(|_| splitmix(&mut state)).collect();
    let data: Vec<u32> = keys64.iter().map(|&k| k as u32).collect();
    let flags: Vec<u32> = keys64.iter().map(|&k| (k >> 40) as u32 & 1).collect();
    let values: Vec<u32> = (0..n as u32).collect();
    let mut profiler = Profiler::new(&ctx)?;
    let mut rows = Vec::new();
    let mut row = |name: String, profiler: &mut Profiler, cpu_ms: f64, ok: bool| -> Result<()> {
        if !ok {
            bail!("{name}: the GPU result differs from the CPU reference");
        }
        let gpu_ms: f64 = profiler.resolve()?.iter().map(|p| p.gpu_ms).sum();
        rows.push(PrimitiveRow {
            gpu_melem_s: n as f64 / gpu_ms / 1e3,
            cpu_melem_s: n as f64 / cpu_ms / 1e3,
            gpu_over_cpu: cpu_ms / gpu_ms,
            primitive: name,
            elements: n as u64,
            gpu_ms,
            cpu_ms,
        });
        Ok(())
    };
    let timed = |f: &mut dyn FnMut()| {
        let t = Instant::now();
        f();
        t.elapsed().as_secs_f64() * 1e3
    };
    for bits in [4, 8] {
        let options = PrimitiveOptions {
            radix_bits: bits,
            ..PrimitiveOptions::default()
        };
        let prims = Primitives::with_options(&ctx, options)?;
        if bits == 4 {
            let got = prims.exclusive_scan(&data, Some(&mut profiler))?;
            let mut want = Default::default();
            let cpu = timed(&mut || want = reference::exclusive_scan(&data));
            row("exclusive scan u32".into(), &mut profiler, cpu, got == want)?;
            let got = prims.compact(&data, &flags, 64, Some(&mut profiler))?;
            let mut want = Vec::new();
            let cpu = timed(&mut || want = reference::compact(&data, &flags));
            row(
                "compaction, 50% kept".into(),
                &mut profiler,
                cpu,
                got.0 == want,
            )?;
        }
        let got = prims.sort_u32(&data, &values, Some(&mut profiler))?;
        let mut want = Default::default();
        let cpu = timed(&mut || want = reference::sort_pairs(&data, &values));
        let name = format!("radix sort u32 keys + values, {bits}-bit digits");
        row(name, &mut profiler, cpu, got == want)?;
        let got = prims.sort_u64(&keys64, &values, Some(&mut profiler))?;
        let mut want = Default::default();
        let cpu = timed(&mut || want = reference::sort_pairs(&keys64, &values));
        let name = format!("radix sort u64 keys + values, {bits}-bit digits");
        row(name, &mut profiler, cpu, got == want)?;
    }
    let info = ctx.info();
    let mut md = format!(
        "GPU primitives on {} (subgroup size {}), 2^{} elements; GPU = profiled passes, \
         CPU = single-threaded reference\n\n\
         | primitive | GPU ms | GPU M elem/s | CPU ms | CPU M elem/s | GPU/CPU speed |\n\
         |---|---|---|---|---|---|\n",
        info.name, info.subgroup_size, args.log2
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {:.1} | {:.2} | {:.1} | {:.2} | {:.3} |\n",
            r.primitive, r.gpu_ms, r.gpu_melem_s, r.cpu_ms, r.cpu_melem_s, r.gpu_over_cpu
        ));
    }
    print!("{md}");
    let report = PrimitivesReport {
        device: info.name.clone(),
        subgroup_size: info.subgroup_size,
        rows,
        passes: profiler.table(),
    };
    eprint!("{}", report.passes);
    write_outputs(&args.json, &report, &args.markdown, &md)
}
