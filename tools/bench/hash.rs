//! `voxdag bench hash`: the dissertation's Table 4.2 protocol for the GPU slab hash tables —
//! fill a table with 2^25 items, search 2^23 items at 25/50/75% hit rates, insert 2^23 new items —
//! per layout, item size (1..=10 words) and load factor (items per bucket, Figure 4.6), with GPU
//! timestamps, memory, and in the same run a CPU baseline on the same items (a rayon-parallel
//! `dashmap` set, plus the sequential CPU reference table on a smaller fill). Every answer is
//! verified; a wrong one fails the run.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use clap::Args;
use dashmap::DashSet;
use image::{Rgb, RgbImage};
use indicatif::ProgressBar;
use rayon::prelude::*;
use rustc_hash::FxBuildHasher;
use serde::Serialize;
use voxdag::gpu::{Buffer, GpuContext, GpuOptions, MemLocation, Profiler};
use voxdag::hash::layout::{fmix32, HANDLE_MISS};
use voxdag::hash::{GpuHashTable, HashTableConfig, HashVariant, ReferenceTable};

use super::write_outputs;
use crate::commands::progress_bar;

/// Arguments of `voxdag bench hash`.
#[derive(Args)]
pub struct BenchHashArgs {
    /// Table layouts: atomic64, ticket_board, accel32, accel8.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "atomic64,ticket_board,accel32,accel8"
    )]
    variants: Vec<String>,
    /// Item sizes in 32-bit words (1..=10).
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,4,5,6,7,8,9,10")]
    item_words: Vec<u32>,
    /// Load factors: items per bucket after the fill (Figure 4.6 sweeps these).
    #[arg(long, value_delimiter = ',', default_value = "96")]
    load_factor: Vec<u32>,
    /// Scale every size down 16x (fill 2^21, search and insert 2^19).
    #[arg(long)]
    quick: bool,
    /// Items in the fill as a power of two (default 25, 21 with --quick); searches and the
    /// insert use a quarter of that.
    #[arg(long, hide = true)]
    fill_log2: Option<u32>,
    /// Largest fill of the sequential CPU reference table, as a power of two.
    #[arg(long, default_value_t = 21)]
    reference_fill_log2: u32,
    /// JSON output file.
    #[arg(long, default_value = "out/bench-hash.json")]
    json: PathBuf,
    /// Markdown output file.
    #[arg(long, default_value = "out/bench-hash.md")]
    markdown: PathBuf,
    /// Chart (PNG): insert M items/s per variant and item size.
    #[arg(long, default_value = "out/bench-hash.png")]
    chart: PathBuf,
}

impl BenchHashArgs {
    /// The output files, checked before the work starts.
    pub(super) fn outputs(&self) -> Vec<&std::path::Path> {
        vec![
            self.json.as_path(),
            self.markdown.as_path(),
            self.chart.as_path(),
        ]
    }
}

/// Search hit rates of Table 4.2, in percent.
const HIT_RATES: [u32; 3] = [25, 50, 75];

/// Search times per hit rate, keyed "25", "50", "75".
#[derive(Serialize, Clone, Default)]
struct PerHitRate {
    #[serde(rename = "25")]
    p25: f64,
    #[serde(rename = "50")]
    p50: f64,
    #[serde(rename = "75")]
    p75: f64,
}

impl PerHitRate {
    fn set(&mut self, rate: u32, value: f64) {
        match rate {
            25 => self.p25 = value,
            50 => self.p50 = value,
            _ => self.p75 = value,
        }
    }
}

/// One (variant, item size, load factor) measurement.
#[derive(Serialize, Clone)]
struct HashRow {
    variant: String,
    item_words: u32,
    load_factor: u32,
    device: String,
    fill_items: u64,
    batch_items: u64,
    fill_ms: f64,
    insert_ms: f64,
    insert_mitems_s: f64,
    search_ms: PerHitRate,
    search_mitems_s: PerHitRate,
    /// Device memory of the table (bucket heads + slab pool), MiB.
    memory_mib: f64,
    /// Memory of the slabs in use plus the heads, MiB.
    used_mib: f64,
    cpu_threads: usize,
    cpu_insert_ms: f64,
    cpu_insert_mitems_s: f64,
    insert_ratio_gpu_cpu: f64,
    reference_fill_items: u64,
    reference_insert_mitems_s: f64,
}

/// Word `j` of item `k` of `w` words: word 0 is a bijection of `k + 1` (distinct, never zero,
/// so every layout stores it), the others pseudo-random.
fn item_word(k: u64, j: u32, w: u32) -> u32 {
    if j == 0 {
        fmix32(k as u32 + 1)
    } else {
        fmix32((k as u32).wrapping_mul(w) ^ j.wrapping_mul(0x9e37_79b9) ^ 0x5bd1_e995)
    }
}

/// Items `indices` (each `w` words), generated in parallel.
fn make_items(indices: &[u64], w: u32) -> Vec<u32> {
    let mut out = vec![0u32; indices.len() * w as usize];
    out.par_chunks_mut(w as usize)
        .zip(indices.par_iter())
        .for_each(|(dst, &k)| {
            for (j, word) in dst.iter_mut().enumerate() {
                *word = item_word(k, j as u32, w);
            }
        });
    out
}

/// The item indices of one run: the fill is `0..fill`, the new items `fill..fill + batch`, the
/// absent items used by the searches `fill + batch..fill + 2 * batch`.
struct Workload {
    fill: u64,
    batch: u64,
}

impl Workload {
    fn fill_indices(&self) -> Vec<u64> {
        (0..self.fill).collect()
    }

    fn new_indices(&self) -> Vec<u64> {
        (self.fill..self.fill + self.batch).collect()
    }

    /// A search batch: `rate`% random fill items (hits), the rest absent items, shuffled.
    fn search_indices(&self, rate: u32) -> Vec<u64> {
        let hits = self.batch * rate as u64 / 100;
        let mut out: Vec<u64> = (0..self.batch)
            .map(|i| {
                let r = fmix32(i as u32 ^ rate.wrapping_mul(0x2545_f491)) as u64;
                if i < hits {
                    (r * 0x9e37 + i) % self.fill
                } else {
                    self.fill + self.batch + i
                }
            })
            .collect();
        // Deterministic Fisher-Yates shuffle.
        for i in (1..out.len()).rev() {
            let j = fmix32(i as u32 ^ 0x68e3_1da4) as usize % (i + 1);
            out.swap(i, j);
        }
        out
    }
}

fn parse_variant(name: &str) -> Result<HashVariant> {
    HashVariant::ALL
        .into_iter()
        .find(|v| v.name() == name)
        .with_context(|| {
            format!("unknown variant {name:?} (atomic64, ticket_board, accel32, accel8)")
        })
}

/// GPU time of the passes named `name` resolved since the last call, in ms (then forgets them).
fn take_pass_ms(profiler: &mut Profiler, name: &str) -> f64 {
    let ms = profiler
        .passes()
        .iter()
        .filter(|p| p.name == name)
        .map(|p| p.gpu_ms)
        .sum();
    profiler.clear();
    ms
}

/// `voxdag bench hash`.
pub fn bench_hash(args: &BenchHashArgs, quiet: bool) -> Result<()> {
    let variants: Vec<HashVariant> = args
        .variants
        .iter()
        .map(|v| parse_variant(v))
        .collect::<Result<_>>()?;
    for &w in &args.item_words {
        ensure!(
            (1..=10).contains(&w),
            "item size {w} is outside 1..=10 words"
        );
    }
    for &lf in &args.load_factor {
        ensure!(lf >= 1, "a load factor is at least 1 item per bucket");
    }
    let fill_log2 = args.fill_log2.unwrap_or(if args.quick { 21 } else { 25 });
    ensure!(
        (4..=28).contains(&fill_log2),
        "fill of 2^{fill_log2} items is outside 2^4..=2^28"
    );
    let workload = Workload {
        fill: 1 << fill_log2,
        batch: 1 << (fill_log2 - 2),
    };
    let context = GpuContext::new(&GpuOptions::default())?;
    let device = context.info().name.clone();
    let mut profiler = Profiler::new(&context)?;
    ensure!(
        profiler.is_available(),
        "the device has no timestamp queries"
    );
    let bar = progress_bar(quiet);
    bar.set_length((args.item_words.len() * args.load_factor.len() * variants.len()) as u64);
    bar.set_message("bench hash");
    let mut rows = Vec::new();
    for &w in &args.item_words {
        let (cpu_ms, reference) = cpu_baseline(&workload, w, args.reference_fill_log2, &bar)?;
        let cpu_mitems_s = workload.batch as f64 / cpu_ms / 1e3;
        for &lf in &args.load_factor {
            for &variant in &variants {
                bar.set_message(format!("{} {w}w lf{lf}", variant.name()));
                let mut row = measure_gpu(&context, &mut profiler, variant, w, lf, &workload)
                    .with_context(|| format!("{} with {w}-word items", variant.name()))?;
                row.device = device.clone();
                row.cpu_threads = rayon::current_num_threads();
                row.cpu_insert_ms = cpu_ms;
                row.cpu_insert_mitems_s = cpu_mitems_s;
                row.insert_ratio_gpu_cpu = row.insert_mitems_s / cpu_mitems_s;
                row.reference_fill_items = reference.0;
                row.reference_insert_mitems_s = reference.1;
                bar.suspend(|| {
                    eprintln!(
                    "{} {w} words lf {lf}: insert {:.2} ms ({:.1} M/s, {:.2}x CPU), search {:.2}/{:.2}/{:.2} ms, {:.0} MiB",
                    variant.name(),
                    row.insert_ms,
                    row.insert_mitems_s,
                    row.insert_ratio_gpu_cpu,
                    row.search_ms.p25,
                    row.search_ms.p50,
                    row.search_ms.p75,
                    row.memory_mib
                )
                });
                rows.push(row);
                bar.inc(1);
            }
        }
    }
    bar.finish_and_clear();
    drop(profiler);
    drop(context);
    let md = markdown(&rows, &workload);
    print!("{md}");
    write_chart(&args.chart, &rows, &variants)?;
    write_outputs(&args.json, &rows, &args.markdown, &md)
}

/// Fills a table, times the searches and the insert on the GPU, and verifies every answer.
fn measure_gpu(
    ctx: &std::sync::Arc<GpuContext>,
    profiler: &mut Profiler,
    variant: HashVariant,
    w: u32,
    load_factor: u32,
    workload: &Workload,
) -> Result<HashRow> {
    let fill = workload.fill as u32;
    let batch = workload.batch as u32;
    let buckets = (fill / load_factor).max(1);
    let mut table = GpuHashTable::new(ctx, &HashTableConfig::new(variant, w, buckets))?;
    let handles_buffer =
        |name: &str, n: u32| ctx.create_buffer(name, 4 * n as u64, MemLocation::GpuOnly);

    // Fill.
    let fill_items = ctx.upload("bench fill items", &make_items(&workload.fill_indices(), w))?;
    let fill_handles = handles_buffer("bench fill handles", fill)?;
    profiler.clear();
    table.insert_buffers(&fill_items, &fill_handles, fill, Some(profiler))?;
    let fill_ms = take_pass_ms(profiler, "hash insert");
    let fill_handles_host: Vec<u32> = ctx.download(&fill_handles)?;
    ensure!(
        !fill_handles_host.contains(&HANDLE_MISS),
        "a fill item has no handle"
    );
    verify_dereference(
        ctx,
        &table,
        &fill_handles,
        &workload.fill_indices(),
        w,
        "fill",
    )?;
    drop(fill_items);

    // Searches.
    let mut search_ms = PerHitRate::default();
    let mut search_mitems_s = PerHitRate::default();
    let search_handles = handles_buffer("bench search handles", batch)?;
    for rate in HIT_RATES {
        let indices = workload.search_indices(rate);
        let items = ctx.upload("bench search items", &make_items(&indices, w))?;
        table.search_buffers(&items, &search_handles, batch, Some(profiler))?;
        let ms = take_pass_ms(profiler, "hash search");
        search_ms.set(rate, ms);
        search_mitems_s.set(rate, batch as f64 / ms / 1e3);
        let found: Vec<u32> = ctx.download(&search_handles)?;
        for (&k, &h) in indices.iter().zip(&found) {
            let expected = if k < workload.fill {
                fill_handles_host[k as usize]
            } else {
                HANDLE_MISS
            };
            if h != expected {
                bail!(
                    "search at {rate}% hits: item {k} gave handle {h:#x}, expected {expected:#x}"
                );
            }
        }
    }

    // Insert of new items.
    let new_indices = workload.new_indices();
    let new_items = ctx.upload("bench new items", &make_items(&new_indices, w))?;
    let new_handles = handles_buffer("bench new handles", batch)?;
    table.insert_buffers(&new_items, &new_handles, batch, Some(profiler))?;
    let insert_ms = take_pass_ms(profiler, "hash insert");
    verify_dereference(ctx, &table, &new_handles, &new_indices, w, "insert")?;
    // Every inserted item is found afterwards, at its handle.
    table.search_buffers(&new_items, &search_handles, batch, None)?;
    let (a, b): (Vec<u32>, Vec<u32>) =
        (ctx.download(&search_handles)?, ctx.download(&new_handles)?);
    ensure!(
        a == b,
        "an inserted item is not found at its handle afterwards"
    );

    let occupancy = table.pool().occupancy()?;
    let layout = table.layout();
    let mib = |bytes: f64| bytes / (1024.0 * 1024.0);
    Ok(HashRow {
        variant: variant.name().to_string(),
        item_words: w,
        load_factor,
        device: String::new(),
        fill_items: workload.fill,
        batch_items: workload.batch,
        fill_ms,
        insert_ms,
        insert_mitems_s: batch as f64 / insert_ms / 1e3,
        search_ms,
        search_mitems_s,
        memory_mib: mib(table.gpu_bytes() as f64),
        used_mib: mib(
            (occupancy.allocated_slabs * layout.slab_words as u64 * 4 + 4 * buckets as u64) as f64
        ),
        cpu_threads: 0,
        cpu_insert_ms: 0.0,
        cpu_insert_mitems_s: 0.0,
        insert_ratio_gpu_cpu: 0.0,
        reference_fill_items: 0,
        reference_insert_mitems_s: 0.0,
    })
}

/// Reads the items behind `handles` on the GPU and compares them with the generator.
fn verify_dereference(
    ctx: &std::sync::Arc<GpuContext>,
    table: &GpuHashTable,
    handles: &Buffer,
    indices: &[u64],
    w: u32,
    what: &str,
) -> Result<()> {
    let out = ctx.create_buffer(
        "bench read items",
        4 * w as u64 * indices.len() as u64,
        MemLocation::GpuOnly,
    )?;
    table.read_items_buffers(handles, &out, indices.len() as u32, None)?;
    let read: Vec<u32> = ctx.download(&out)?;
    let bad = read
        .par_chunks_exact(w as usize)
        .zip(indices.par_iter())
        .position_any(|(item, &k)| {
            item.iter()
                .enumerate()
                .any(|(j, &word)| word != item_word(k, j as u32, w))
        });
    if let Some(i) = bad {
        bail!(
            "{what}: the handle of item {} dereferences to another item",
            indices[i]
        );
    }
    Ok(())
}

/// CPU baseline: a rayon-parallel `dashmap` set filled with the same items, then the same new
/// items inserted in parallel (ms); and the sequential CPU reference table's insert throughput
/// (M items/s) after a fill of at most 2^`reference_fill_log2` items. Returns
/// (dashmap insert ms, (reference fill items, reference M items/s)).
fn cpu_baseline(
    workload: &Workload,
    w: u32,
    reference_fill_log2: u32,
    bar: &ProgressBar,
) -> Result<(f64, (u64, f64))> {
    bar.set_message(format!("CPU {w}w"));
    let fill = make_items(&workload.fill_indices(), w);
    let new = make_items(&workload.new_indices(), w);
    let dashmap_ms = match w {
        1 => dashmap_insert::<1>(&fill, &new),
        2 => dashmap_insert::<2>(&fill, &new),
        3 => dashmap_insert::<3>(&fill, &new),
        4 => dashmap_insert::<4>(&fill, &new),
        5 => dashmap_insert::<5>(&fill, &new),
        6 => dashmap_insert::<6>(&fill, &new),
        7 => dashmap_insert::<7>(&fill, &new),
        8 => dashmap_insert::<8>(&fill, &new),
        9 => dashmap_insert::<9>(&fill, &new),
        _ => dashmap_insert::<10>(&fill, &new),
    }?;

    // The reference is sequential and keeps whole super blocks in memory: a smaller fill.
    let ref_fill = workload.fill.min(1 << reference_fill_log2);
    let ref_batch = ref_fill / 4;
    let load_factor = 96;
    let mut reference = ReferenceTable::new(
        HashVariant::TicketBoard,
        w,
        (ref_fill / load_factor).max(1) as u32,
    )?;
    for item in fill[..(ref_fill * w as u64) as usize].chunks_exact(w as usize) {
        reference.insert(item)?;
    }
    let start = Instant::now();
    for item in new[..(ref_batch * w as u64) as usize].chunks_exact(w as usize) {
        reference.insert(item)?;
    }
    let ref_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok((dashmap_ms, (ref_fill, ref_batch as f64 / ref_ms / 1e3)))
}

/// Fills a `DashSet` of `W`-word items in parallel, then times the parallel insert of `new`.
/// Fails if any new item was already present or the set lost one.
fn dashmap_insert<const W: usize>(fill: &[u32], new: &[u32]) -> Result<f64> {
    let key = |c: &[u32]| -> [u32; W] { c.try_into().expect("chunks of W words") };
    let total = (fill.len() + new.len()) / W;
    let set: DashSet<[u32; W], FxBuildHasher> =
        DashSet::with_capacity_and_hasher(total, FxBuildHasher);
    fill.par_chunks_exact(W).for_each(|c| {
        set.insert(key(c));
    });
    let start = Instant::now();
    let fresh = new
        .par_chunks_exact(W)
        .map(|c| set.insert(key(c)) as usize)
        .sum::<usize>();
    let ms = start.elapsed().as_secs_f64() * 1e3;
    ensure!(
        fresh == new.len() / W && set.len() == total,
        "CPU baseline: {fresh} of {} new items inserted, {} in the set of {total}",
        new.len() / W,
        set.len()
    );
    Ok(ms)
}

/// The Markdown table (one row per measurement).
fn markdown(rows: &[HashRow], workload: &Workload) -> String {
    let mut md = format!(
        "Fill {} items, then search {} items at 25/50/75% hits and insert {} new items (GPU timestamps).\n\n",
        workload.fill, workload.batch, workload.batch
    );
    md += "| variant | words | load | insert ms | insert M/s | search ms 25% | 50% | 75% | MiB | used MiB | CPU insert M/s | GPU/CPU | ref M/s |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for r in rows {
        md += &format!(
            "| {} | {} | {} | {:.2} | {:.1} | {:.2} | {:.2} | {:.2} | {:.0} | {:.0} | {:.1} | {:.2} | {:.2} |\n",
            r.variant,
            r.item_words,
            r.load_factor,
            r.insert_ms,
            r.insert_mitems_s,
            r.search_ms.p25,
            r.search_ms.p50,
            r.search_ms.p75,
            r.memory_mib,
            r.used_mib,
            r.cpu_insert_mitems_s,
            r.insert_ratio_gpu_cpu,
            r.reference_insert_mitems_s
        );
    }
    if let Some(r) = rows.first() {
        md += &format!(
            "\nDevice: {}. CPU baseline: dashmap set with {} rayon threads; ref: sequential CPU reference table (Ticket Board, load factor 96) after a fill of {} items.\n",
            r.device, r.cpu_threads, r.reference_fill_items
        );
    }
    md
}

/// Bar colours per variant (Atomic64, Ticket Board, Accel32, Accel8).
const COLOURS: [[u8; 3]; 4] = [[66, 133, 244], [52, 168, 83], [251, 188, 5], [234, 67, 53]];

/// Grouped bars: per (item size, load factor) one bar per variant, height = insert M items/s
/// (scaled to the largest), with a black tick at the CPU baseline's throughput.
fn write_chart(path: &std::path::Path, rows: &[HashRow], variants: &[HashVariant]) -> Result<()> {
    let (bar, gap, height) = (10u32, 14u32, 240u32);
    let mut groups: Vec<(u32, u32)> = rows.iter().map(|r| (r.item_words, r.load_factor)).collect();
    groups.dedup();
    let per_group = variants.len() as u32 * bar;
    let width = gap + groups.len() as u32 * (per_group + gap);
    let top = rows
        .iter()
        .map(|r| r.insert_mitems_s.max(r.cpu_insert_mitems_s))
        .fold(1e-9, f64::max);
    let scale = |v: f64| ((height as f64 * v / top).round() as u32).min(height);
    let mut img = RgbImage::from_pixel(width, height + 20, Rgb([255, 255, 255]));
    for (g, group) in groups.iter().enumerate() {
        let x_group = gap + g as u32 * (per_group + gap);
        for r in rows
            .iter()
            .filter(|r| (r.item_words, r.load_factor) == *group)
        {
            let Some(v) = variants.iter().position(|v| v.name() == r.variant) else {
                continue;
            };
            let x0 = x_group + v as u32 * bar;
            let h = scale(r.insert_mitems_s);
            for x in x0..x0 + bar - 2 {
                for y in (10 + height - h)..(10 + height) {
                    img.put_pixel(x, y, Rgb(COLOURS[v % COLOURS.len()]));
                }
            }
            let cpu_y = 10 + height - scale(r.cpu_insert_mitems_s);
            for x in x_group..x_group + per_group {
                img.put_pixel(x, cpu_y.min(10 + height - 1), Rgb([0, 0, 0]));
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
