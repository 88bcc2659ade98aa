//! Garbage collection of the slab hash tables (engine/hash/gc.rs) on a real device (lavapipe in
//! CI), all four layouts and several item sizes: the GPU leaves exactly the CPU reference's table
//! image, keeps exactly the marked items at their handles, frees the empty slabs, and the table
//! takes inserts afterwards. Fails, not skips, without a device.

mod common;

use std::collections::HashSet;
use std::sync::Arc;

use voxdag::gpu::GpuContext;
use voxdag::hash::gc::{collect_cpu, GcReport, GpuGarbageCollector};
use voxdag::hash::layout::{bucket_of, hash_item};
use voxdag::hash::{GpuHashTable, Handle, HashError, HashTableConfig, HashVariant, TeamMode};

/// Both team modes: the whole subgroup per bucket, and one lane per bucket.
const TEAMS: [TeamMode; 2] = [TeamMode::Subgroup, TeamMode::SingleLane];

/// A table configuration with an explicit team mode.
fn config(variant: HashVariant, words: u32, buckets: u32, team: TeamMode) -> HashTableConfig {
    HashTableConfig {
        team,
        ..HashTableConfig::new(variant, words, buckets)
    }
}

/// `count` distinct items of `words` words with a non-zero first word (storable by every layout).
fn items(
    rng: &mut common::Rng,
    words: usize,
    count: usize,
    avoid: &HashSet<Vec<u32>>,
) -> Vec<Vec<u32>> {
    let mut seen = avoid.clone();
    let mut out = Vec::with_capacity(count);
    while out.len() < count {
        let item: Vec<u32> = (0..words)
            .map(|w| {
                if w == 0 {
                    rng.next() as u32 | 1
                } else {
                    rng.next() as u32
                }
            })
            .collect();
        if seen.insert(item.clone()) {
            out.push(item);
        }
    }
    out
}

fn flat(items: &[Vec<u32>]) -> Vec<u32> {
    items.concat()
}

fn assert_clean(ctx: &Arc<GpuContext>) {
    // Deferred releases wait for the GPU: drain them first.
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
}

/// One full cycle on one layout: insert, collect (GPU vs CPU image), check, insert again.
fn gc_cycle(
    ctx: &Arc<GpuContext>,
    variant: HashVariant,
    words: u32,
    team: TeamMode,
    rng: &mut common::Rng,
) {
    let what = format!("{variant:?} {words} words {team:?}");
    let buckets = 48;
    let mut table = GpuHashTable::new(ctx, &config(variant, words, buckets, team)).unwrap();
    let first = items(rng, words as usize, 3000, &HashSet::new());
    let (handles, _) = table.insert(&flat(&first), None).unwrap();

    // Keep nothing in the lower half of the buckets (their overflow slabs become empty) and
    // every third item elsewhere.
    let keep: Vec<bool> = first
        .iter()
        .enumerate()
        .map(|(i, item)| bucket_of(hash_item(item), buckets) >= buckets / 2 && i % 3 == 0)
        .collect();
    let live: Vec<Handle> = handles
        .iter()
        .zip(&keep)
        .filter(|(_, &k)| k)
        .map(|(h, _)| *h)
        .collect();

    let before = table.download().unwrap();
    let slabs_before = before.walk().unwrap().slabs;
    let mut expected = before.clone();
    let cpu_report = collect_cpu(&mut expected, &live);
    let gc = GpuGarbageCollector::new(ctx, &table).unwrap();
    let lanes = if team == TeamMode::SingleLane {
        1
    } else {
        ctx.info().subgroup_size
    };
    assert_eq!(
        gc.team_size(),
        lanes,
        "{what}: the collector follows the table"
    );
    let report = gc.collect(&mut table, &live, None).unwrap();
    assert_eq!(report, cpu_report, "{what}: GC report");
    assert_eq!(
        report.freed_items as usize,
        keep.iter().filter(|&&k| !k).count(),
        "{what}"
    );
    assert_eq!(
        report.kept_items as usize,
        keep.iter().filter(|&&k| k).count(),
        "{what}"
    );
    assert!(
        report.freed_slabs > 0,
        "{what}: the emptied buckets should free overflow slabs"
    );
    let after = table.download().unwrap();
    assert!(
        after == expected,
        "{what}: GPU table image differs from the CPU reference"
    );

    // Exactly the marked items remain, at their handles; the freed slabs are back in the pool.
    let walk = after.walk().unwrap_or_else(|e| panic!("{what}: {e}"));
    let kept: HashSet<(Handle, Vec<u32>)> = walk.items.into_iter().collect();
    let marked: HashSet<(Handle, Vec<u32>)> = handles
        .iter()
        .zip(&first)
        .zip(&keep)
        .filter(|(_, &k)| k)
        .map(|((h, item), _)| (*h, item.clone()))
        .collect();
    assert!(
        kept == marked,
        "{what}: table holds other items than the marked ones"
    );
    assert_eq!(
        walk.slabs,
        slabs_before - report.freed_slabs as u64,
        "{what}"
    );
    let occupancy = table.pool().occupancy().unwrap();
    assert_eq!(occupancy.allocated_slabs, walk.slabs, "{what}");
    let found = table.search(&flat(&first), None).unwrap();
    for ((found, handle), &k) in found.iter().zip(&handles).zip(&keep) {
        assert_eq!(*found, k.then_some(*handle), "{what}: search after GC");
    }

    // Inserts after GC reuse the freed slabs without handing one out twice (walk checks it).
    let avoid: HashSet<Vec<u32>> = first.iter().cloned().collect();
    let second = items(rng, words as usize, 2000, &avoid);
    let (new_handles, _) = table.insert(&flat(&second), None).unwrap();
    let walk = table
        .download()
        .unwrap()
        .walk()
        .unwrap_or_else(|e| panic!("{what}: {e}"));
    assert_eq!(walk.items.len(), marked.len() + second.len(), "{what}");
    assert_eq!(
        table.read_items(&new_handles).unwrap(),
        flat(&second),
        "{what}"
    );
    let found = table.search(&flat(&second), None).unwrap();
    assert!(
        found.iter().zip(&new_handles).all(|(f, h)| *f == Some(*h)),
        "{what}"
    );

    // A second cycle starts from clear active words: keeping everything frees nothing.
    let everything: Vec<Handle> = walk.items.iter().map(|(h, _)| *h).collect();
    let report = gc.collect(&mut table, &everything, None).unwrap();
    let kept_all = GcReport {
        kept_items: everything.len() as u32,
        ..GcReport::default()
    };
    assert_eq!(report, kept_all, "{what}: second cycle");
}

#[test]
fn gc_keeps_exactly_the_marked_items_for_every_layout() {
    let ctx = common::gpu();
    let mut rng = common::Rng(0x6c);
    for team in TEAMS {
        for variant in HashVariant::ALL {
            for words in [1, 2, 3, 7, 10] {
                gc_cycle(&ctx, variant, words, team, &mut rng);
            }
        }
    }
    assert_clean(&ctx);
}

#[test]
fn gc_of_nothing_live_empties_the_table_and_frees_every_slab() {
    let ctx = common::gpu();
    for team in TEAMS {
        nothing_live(&ctx, team);
    }
    assert_clean(&ctx);
}

fn nothing_live(ctx: &Arc<GpuContext>, team: TeamMode) {
    let mut rng = common::Rng(3);
    let buckets = 16;
    let mut table =
        GpuHashTable::new(ctx, &config(HashVariant::AccelHash8, 4, buckets, team)).unwrap();
    let batch = items(&mut rng, 4, 2000, &HashSet::new());
    let (stale, _) = table.insert(&flat(&batch), None).unwrap();
    let gc = GpuGarbageCollector::new(ctx, &table).unwrap();
    let report = gc.collect(&mut table, &[], None).unwrap();
    assert_eq!(report.freed_items, 2000);
    let image = table.download().unwrap();
    let walk = image.walk().unwrap();
    assert!(walk.items.is_empty());
    assert_eq!(walk.slabs, 0, "every slab freed, first slabs too");
    assert_eq!(walk.max_chain, 0);

    // Stale handles: all name freed slabs, counted and ignored (a free slab stays all zeros).
    let mut expected = image.clone();
    let cpu = collect_cpu(&mut expected, &stale);
    let report = gc.collect(&mut table, &stale, None).unwrap();
    assert_eq!(report, cpu);
    let in_free_slabs = stale
        .iter()
        .filter(|h| !image.is_allocated(h.slab()))
        .count();
    assert_eq!(in_free_slabs, stale.len());
    assert_eq!(report.bad_handles as usize, in_free_slabs);
    assert!(
        table.download().unwrap() == expected,
        "{team:?}: stale handles changed the table"
    );
}

#[test]
fn handles_beyond_the_pool_are_rejected() {
    let ctx = common::gpu();
    for team in TEAMS {
        let mut table =
            GpuHashTable::new(&ctx, &config(HashVariant::TicketBoard, 2, 8, team)).unwrap();
        beyond_the_pool(&ctx, &mut table);
    }
    assert_clean(&ctx);
}

fn beyond_the_pool(ctx: &Arc<GpuContext>, table: &mut GpuHashTable) {
    let gc = GpuGarbageCollector::new(ctx, table).unwrap();
    let beyond = Handle::new(table.pool().capacity_slabs() as u32 + 5, 0);
    assert!(matches!(
        gc.collect(table, &[beyond], None),
        Err(HashError::InvalidArgument(_))
    ));
    // The sentinels are skipped, not errors.
    let skipped = [
        Handle(voxdag::hash::HANDLE_MISS),
        Handle(voxdag::hash::HANDLE_INVALID),
    ];
    assert_eq!(
        gc.collect(table, &skipped, None).unwrap(),
        GcReport::default()
    );
}

/// `voxdag bench hash` end to end at a tiny size (the hidden `--fill-log2`): every variant, two
/// item sizes, two load factors; the run verifies its own answers and writes all three outputs.
/// (Here rather than in tests/cli.rs to keep the hash work in the files it owns.)
#[test]
fn bench_hash_cli_runs_and_verifies_at_a_tiny_size() {
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    let (json, md, png) = (out("h.json"), out("h.md"), out("h.png"));
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_voxdag"))
        .args(["--quiet", "bench", "hash", "--quick", "--fill-log2", "12"])
        .args(["--item-words", "1,3", "--load-factor", "16,96"])
        .args(["--json", &json, "--markdown", &md, "--chart", &png])
        .output()
        .unwrap();
    assert!(
        output.status.success(),
        "bench hash failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let rows: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 4 * 2 * 2);
    for row in rows {
        for key in [
            "insert_ms",
            "insert_mitems_s",
            "memory_mib",
            "cpu_insert_mitems_s",
            "insert_ratio_gpu_cpu",
        ] {
            assert!(row[key].as_f64().is_some_and(|v| v > 0.0), "{key} in {row}");
        }
        for rate in ["25", "50", "75"] {
            assert!(
                row["search_ms"][rate].as_f64().is_some_and(|v| v > 0.0),
                "{row}"
            );
        }
    }
    assert!(std::fs::read_to_string(&md)
        .unwrap()
        .contains("| accel8 | 3 | 96 |"));
    assert!(image::open(&png).is_ok());
}

/// GC of a table keeping every other item, both team modes, Atomic64 and Acceleration Hash 8:
/// the GPU image equals the CPU reference's; GPU pass times printed (`--nocapture`).
#[test]
fn team_modes_collect_a_large_table_exactly_and_report_their_times() {
    let ctx = common::gpu();
    let count = 1usize << common::hash_timing_log2();
    let buckets = (count / 64) as u32; // two slabs per bucket
    let mut rng = common::Rng(0x9c);
    let batch = items(&mut rng, 2, count, &HashSet::new());
    for variant in [HashVariant::Atomic64, HashVariant::AccelHash8] {
        for team in TEAMS {
            let mut table = GpuHashTable::new(&ctx, &config(variant, 2, buckets, team)).unwrap();
            let (handles, _) = table.insert(&flat(&batch), None).unwrap();
            let live: Vec<Handle> = handles.iter().step_by(2).copied().collect();
            let mut expected = table.download().unwrap();
            let cpu = collect_cpu(&mut expected, &live);
            let gc = GpuGarbageCollector::new(&ctx, &table).unwrap();
            // A first run compiles the shaders (lavapipe compiles at the first dispatch).
            gc.collect(&mut table, &handles, None).unwrap();
            let mut profiler = voxdag::gpu::Profiler::new(&ctx).unwrap();
            let report = gc.collect(&mut table, &live, Some(&mut profiler)).unwrap();
            assert_eq!(report, cpu, "{variant:?} {team:?}");
            assert!(
                table.download().unwrap() == expected,
                "{variant:?} {team:?}: GPU table image differs from the CPU reference"
            );
            let times: Vec<String> = profiler
                .passes()
                .iter()
                .map(|p| format!("{} {:.2} ms", p.name, p.gpu_ms))
                .collect();
            println!(
                "gc {variant:?} {count} 2-word items in {buckets} buckets, {team:?} (team {}): {}",
                gc.team_size(),
                times.join(", ")
            );
        }
    }
    assert_clean(&ctx);
}

/// After a collection, inserts fill the slots it freed before they allocate: GC clears the
/// insert hints (which would start the walk past the holes) and, for Atomic64, makes inserts scan
/// whole slabs (its items no longer form a prefix). One bucket of 3 full slabs, every other item
/// in an odd slot collected (no slab empties), then as many new items as were freed: still 3 slabs.
#[test]
fn inserts_after_gc_fill_the_freed_slots_first() {
    let ctx = common::gpu();
    let mut rng = common::Rng(0x51);
    for team in TEAMS {
        for variant in HashVariant::ALL {
            for words in [1, 3] {
                let what = format!("{variant:?} {words} words {team:?}");
                let mut table = GpuHashTable::new(&ctx, &config(variant, words, 1, team)).unwrap();
                let first = items(&mut rng, words as usize, 96, &HashSet::new());
                let (handles, _) = table.insert(&flat(&first), None).unwrap();
                assert_eq!(table.download().unwrap().walk().unwrap().slabs, 3, "{what}");
                // Even slots stay: every slab keeps 16 items.
                let live: Vec<Handle> = handles
                    .iter()
                    .filter(|h| h.slot() % 2 == 0)
                    .copied()
                    .collect();
                let gc = GpuGarbageCollector::new(&ctx, &table).unwrap();
                let report = gc.collect(&mut table, &live, None).unwrap();
                assert_eq!((report.freed_items, report.freed_slabs), (48, 0), "{what}");
                let avoid: HashSet<Vec<u32>> = first.iter().cloned().collect();
                let second = items(&mut rng, words as usize, 48, &avoid);
                let (new_handles, _) = table.insert(&flat(&second), None).unwrap();
                let walk = table.download().unwrap().walk().unwrap();
                assert_eq!(
                    walk.slabs, 3,
                    "{what}: inserts allocated instead of filling holes"
                );
                assert_eq!(walk.items.len(), 96, "{what}");
                assert_eq!(
                    table.read_items(&new_handles).unwrap(),
                    flat(&second),
                    "{what}"
                );
            }
        }
    }
    assert_clean(&ctx);
}
