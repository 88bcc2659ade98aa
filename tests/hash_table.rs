//! GPU slab hash tables against the CPU reference, on a real device (lavapipe in CI): every
//! variant x item size 1..=10, hit/miss mixes, find-or-insert, pool exhaustion and retry, and a
//! structural walk of the downloaded tables. Fails, not skips, without a device. Every test ends
//! with zero validation messages and zero live allocations.

mod common;

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use voxdag::gpu::{GpuContext, MemLocation, Profiler};
use voxdag::hash::claim::{ClaimTable, Claims};
use voxdag::hash::gc::GpuGarbageCollector;
use voxdag::hash::layout::HashPush;
use voxdag::hash::layout::SUPER_BLOCK_BITMASK_WORDS;
use voxdag::hash::mixed::{MixedPasses, MIXED_SIZES};
use voxdag::hash::{
    GpuHashTable, Handle, HashError, HashTableConfig, HashVariant, InsertCheck, ReferenceTable,
    TableImage, TeamMode, HANDLE_INVALID, HANDLE_MISS,
};

fn assert_clean(ctx: &Arc<GpuContext>) {
    // Deferred releases wait for the GPU: drain them first.
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

/// `n` distinct random items of `w` words (seeded); every item has a non-zero first word so
/// all layouts accept them. Small word values make items share prefixes now and then.
fn random_items(n: usize, w: u32, seed: u64, taken: &mut HashSet<Vec<u32>>) -> Vec<Vec<u32>> {
    let mut state = seed;
    let mut next = || {
        state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        (z ^ (z >> 31)) as u32
    };
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let item: Vec<u32> = (0..w)
            .map(|i| {
                let r = next();
                let v = if r & 3 == 0 { r >> 28 } else { r };
                if i == 0 {
                    v | 1
                } else {
                    v
                }
            })
            .collect();
        if taken.insert(item.clone()) {
            out.push(item);
        }
    }
    out
}

fn flat(items: &[Vec<u32>]) -> Vec<u32> {
    items.concat()
}

/// The walk's handle -> item map; asserts no item is stored twice.
fn walk_map(image: &TableImage) -> HashMap<Handle, Vec<u32>> {
    let report = image.walk().unwrap_or_else(|e| panic!("table walk: {e}"));
    let mut seen = HashSet::new();
    for (_, item) in &report.items {
        assert!(seen.insert(item.clone()), "item {item:?} stored twice");
    }
    report.items.into_iter().collect()
}

/// GPU and CPU tables on the same workload: insert, searches with hits and misses,
/// find-or-insert of half old, half new items, dereference, walk.
fn check_variant(ctx: &Arc<GpuContext>, variant: HashVariant, w: u32, team: TeamMode) {
    let buckets = 11;
    let mut taken = HashSet::new();
    let first = random_items(1200, w, 7 * w as u64 + variant.id() as u64, &mut taken);
    let absent = random_items(300, w, 1000 + w as u64, &mut taken);
    let fresh = random_items(400, w, 2000 + w as u64, &mut taken);
    let ctx_msg = format!("{variant:?} w={w} {team:?}");

    let config = HashTableConfig {
        team,
        ..HashTableConfig::new(variant, w, buckets)
    };
    let mut gpu = GpuHashTable::new(ctx, &config).unwrap();
    let mut cpu = ReferenceTable::new(variant, w, buckets).unwrap();

    let (handles, report) = gpu.insert(&flat(&first), None).unwrap();
    assert_eq!(report.rounds, 1, "{ctx_msg}");
    for item in &first {
        cpu.insert(item).unwrap();
    }
    let unique: HashSet<Handle> = handles.iter().copied().collect();
    assert_eq!(unique.len(), handles.len(), "{ctx_msg}: handles repeat");

    // Hits and misses interleaved.
    let mut queries = Vec::new();
    for (i, item) in absent.iter().enumerate() {
        queries.push(item.clone());
        queries.push(first[i * 3].clone());
    }
    let found = gpu.search(&flat(&queries), None).unwrap();
    for (q, f) in queries.iter().zip(&found) {
        assert_eq!(f.is_some(), cpu.search(q).is_some(), "{ctx_msg}: {q:?}");
    }
    for (i, _) in absent.iter().enumerate() {
        assert_eq!(
            found[2 * i + 1],
            Some(handles[i * 3]),
            "{ctx_msg}: hit handle"
        );
    }

    // Find-or-insert: old items keep their handles, new ones get new slots.
    let mut mixed = Vec::new();
    for (i, item) in fresh.iter().enumerate() {
        mixed.push(item.clone());
        mixed.push(first[i].clone());
    }
    let (mixed_handles, _) = gpu.find_or_insert(&flat(&mixed), None).unwrap();
    cpu.find_or_insert(&flat(&mixed)).unwrap();
    for i in 0..fresh.len() {
        assert_eq!(
            mixed_handles[2 * i + 1],
            handles[i],
            "{ctx_msg}: old handle changed"
        );
        assert!(
            !unique.contains(&mixed_handles[2 * i]),
            "{ctx_msg}: new item got an old handle"
        );
    }

    // Dereference every handle on the GPU.
    let all_handles: Vec<Handle> = handles.iter().chain(&mixed_handles).copied().collect();
    let read = gpu.read_items(&all_handles).unwrap();
    let expected: Vec<u32> = first.iter().chain(&mixed).flatten().copied().collect();
    assert_eq!(read, expected, "{ctx_msg}: read_items");

    // Structure: same item set as the reference, every handle names its item.
    let image = gpu.download().unwrap();
    let gpu_map = walk_map(&image);
    let cpu_map = walk_map(cpu.image());
    let gpu_items: HashSet<&Vec<u32>> = gpu_map.values().collect();
    let cpu_items: HashSet<&Vec<u32>> = cpu_map.values().collect();
    assert_eq!(gpu_items, cpu_items, "{ctx_msg}: item sets differ");
    assert_eq!(gpu_map.len(), first.len() + fresh.len());
    for (h, item) in handles.iter().zip(&first) {
        assert_eq!(gpu_map.get(h), Some(item), "{ctx_msg}: handle {h:?}");
    }
    assert_eq!(image.status.exhausted, 0);
    let occupancy = gpu.pool().occupancy().unwrap();
    assert_eq!(
        occupancy.allocated_slabs,
        image.status.allocated_slabs as u64
    );
}

/// Both team modes: the cooperative subgroup algorithm and one lane per item.
fn check_all_sizes(variant: HashVariant) {
    let ctx = common::gpu();
    for team in [TeamMode::Subgroup, TeamMode::SingleLane] {
        for w in 1..=10 {
            check_variant(&ctx, variant, w, team);
        }
    }
    assert_clean(&ctx);
}

#[test]
fn atomic64_matches_reference_for_all_item_sizes() {
    check_all_sizes(HashVariant::Atomic64);
}

#[test]
fn ticket_board_matches_reference_for_all_item_sizes() {
    check_all_sizes(HashVariant::TicketBoard);
}

#[test]
fn accel32_matches_reference_for_all_item_sizes() {
    check_all_sizes(HashVariant::AccelHash32);
}

#[test]
fn accel8_matches_reference_for_all_item_sizes() {
    check_all_sizes(HashVariant::AccelHash8);
}

/// More buckets than one super block has slabs: without growth before the insert the first
/// round runs out of slabs; the host grows the pool and retries only the left-over items.
#[test]
fn exhaustion_grows_the_pool_and_retries() {
    let ctx = common::gpu();
    let cases = [
        (HashVariant::Atomic64, TeamMode::Subgroup),
        (HashVariant::AccelHash8, TeamMode::SingleLane),
    ];
    for (variant, team) in cases {
        let buckets = 24_000;
        let config = HashTableConfig {
            grow_before_insert: false,
            team,
            ..HashTableConfig::new(variant, 2, buckets)
        };
        let mut gpu = GpuHashTable::new(&ctx, &config).unwrap();
        let items = random_items(30_000, 2, 99, &mut HashSet::new());
        let (handles, report) = gpu.insert(&flat(&items), None).unwrap();
        assert!(report.rounds >= 2, "{variant:?}: {report:?}");
        assert!(report.retried_items > 0);
        assert!(report.super_blocks >= 2);
        let found = gpu.search(&flat(&items), None).unwrap();
        assert_eq!(found, handles.iter().copied().map(Some).collect::<Vec<_>>());
        let map = walk_map(&gpu.download().unwrap());
        assert_eq!(map.len(), items.len());
        // Every slab handed out once: the walk checks no slab is linked twice and that the
        // bitmasks mark exactly the linked slabs.
        let occupancy = gpu.pool().occupancy().unwrap();
        assert_eq!(occupancy.super_blocks, report.super_blocks);
        assert!(occupancy.allocated_slabs > 16_384);
    }
    assert_clean(&ctx);
}

/// A pool that may not grow enough reports exhaustion instead of losing items.
#[test]
fn exhaustion_without_room_is_an_error() {
    let ctx = common::gpu();
    let config = HashTableConfig {
        grow_before_insert: false,
        max_insert_rounds: 1,
        ..HashTableConfig::new(HashVariant::TicketBoard, 1, 30_000)
    };
    let mut gpu = GpuHashTable::new(&ctx, &config).unwrap();
    // ~19 000 buckets get an item: more than the 16 384 slabs of the one super block.
    let items = random_items(30_000, 1, 5, &mut HashSet::new());
    match gpu.insert(&flat(&items), None) {
        Err(HashError::Exhausted { items: left, .. }) => assert!(left > 0),
        Err(e) => panic!("expected exhaustion, got {e}"),
        Ok((_, report)) => panic!("expected exhaustion, got {report:?}"),
    }
    // What was placed is intact and findable.
    let map = walk_map(&gpu.download().unwrap());
    let placed: HashSet<Vec<u32>> = map.into_values().collect();
    let found = gpu.search(&flat(&items), None).unwrap();
    for (item, f) in items.iter().zip(&found) {
        assert_eq!(f.is_some(), placed.contains(item));
    }
    drop(gpu);
    assert_clean(&ctx);
}

/// Atomic64 rejects items with a zero prefix: an error from the host API, `HANDLE_INVALID`
/// from the GPU-resident pass.
#[test]
fn atomic64_zero_prefix_items_are_rejected() {
    let ctx = common::gpu();
    let mut gpu =
        GpuHashTable::new(&ctx, &HashTableConfig::new(HashVariant::Atomic64, 3, 4)).unwrap();
    match gpu.insert(&[1, 2, 3, 0, 0, 7], None) {
        Err(HashError::InvalidItem { index: 1, .. }) => {}
        other => panic!("expected an invalid item, got {other:?}"),
    }
    let items = ctx
        .upload("items", &[1u32, 2, 3, 0, 0, 7, 0, 5, 0])
        .unwrap();
    let handles = ctx
        .create_buffer("handles", 12, MemLocation::GpuOnly)
        .unwrap();
    let report = gpu.insert_buffers(&items, &handles, 3, None).unwrap();
    assert_eq!(report.invalid_items, 1);
    let raw: Vec<u32> = ctx.download(&handles).unwrap();
    assert_eq!(raw[1], HANDLE_INVALID);
    assert!(raw[0] != HANDLE_MISS && raw[2] != HANDLE_MISS && raw[0] != raw[2]);
    gpu.search_buffers(&items, &handles, 3, None).unwrap();
    let raw: Vec<u32> = ctx.download(&handles).unwrap();
    assert_eq!(raw[1], HANDLE_MISS);
    drop((gpu, items, handles));
    assert_clean(&ctx);
}

/// Passes show up in the profiler under their names.
#[test]
fn passes_are_profiled() {
    let ctx = common::gpu();
    let mut profiler = Profiler::new(&ctx).unwrap();
    let mut gpu =
        GpuHashTable::new(&ctx, &HashTableConfig::new(HashVariant::TicketBoard, 4, 64)).unwrap();
    let items = flat(&random_items(3000, 4, 3, &mut HashSet::new()));
    gpu.insert(&items, Some(&mut profiler)).unwrap();
    gpu.search(&items, Some(&mut profiler)).unwrap();
    let names: Vec<&str> = profiler.passes().iter().map(|p| p.name.as_str()).collect();
    assert!(
        names.contains(&"hash insert") && names.contains(&"hash search"),
        "{names:?}"
    );
    if profiler.is_available() {
        assert!(profiler.passes().iter().all(|p| p.gpu_ms > 0.0));
    }
    drop((gpu, profiler));
    assert_clean(&ctx);
}

/// A bad configuration is an error, not a panic.
#[test]
fn bad_configurations_are_errors() {
    let ctx = common::gpu();
    for (w, buckets) in [(0, 4), (11, 4), (2, 0)] {
        let config = HashTableConfig::new(HashVariant::AccelHash32, w, buckets);
        assert!(matches!(
            GpuHashTable::new(&ctx, &config),
            Err(HashError::Config(_))
        ));
    }
    let gpu =
        GpuHashTable::new(&ctx, &HashTableConfig::new(HashVariant::AccelHash32, 3, 4)).unwrap();
    assert!(matches!(
        gpu.search(&[1, 2], None),
        Err(HashError::InvalidArgument(_))
    ));
    drop(gpu);
    assert_clean(&ctx);
}

/// Duplicates inside one insert batch each get their own slot (documented behaviour; the
/// duplicate-detection table exists for callers that need one copy): every copy is readable and
/// the walk sees the item as often as it was inserted.
#[test]
fn duplicates_in_one_batch_get_separate_slots() {
    let ctx = common::gpu();
    for team in [TeamMode::Subgroup, TeamMode::SingleLane] {
        let config = HashTableConfig {
            team,
            ..HashTableConfig::new(HashVariant::AccelHash32, 2, 3)
        };
        let mut gpu = GpuHashTable::new(&ctx, &config).unwrap();
        let batch = [5u32, 6, 7, 8, 5, 6, 5, 6];
        let (handles, _) = gpu.insert(&batch, None).unwrap();
        let distinct: HashSet<Handle> = handles.iter().copied().collect();
        assert_eq!(distinct.len(), 4, "{team:?}");
        assert_eq!(gpu.read_items(&handles).unwrap(), batch.to_vec());
        let report = gpu.download().unwrap().walk().unwrap();
        let copies = report
            .items
            .iter()
            .filter(|(_, it)| it == &vec![5, 6])
            .count();
        assert_eq!(copies, 3, "{team:?}");
        // A search finds one of the copies.
        let found = gpu.search(&[5, 6], None).unwrap()[0].unwrap();
        assert!(handles.contains(&found));
    }
    assert_clean(&ctx);
}

/// A find-or-insert batch: fresh item `i` `1 + i % copies` times, stored item `i % len` after
/// every `stored_every`-th fresh one, scattered by a fixed permutation so that equal items race
/// in different lanes; with the handle each stored item must keep (None for fresh ones).
fn repeated_batch(
    fresh: &[Vec<u32>],
    stored: &[Vec<u32>],
    stored_handles: &[Handle],
    copies: usize,
    stored_every: usize,
) -> (Vec<Vec<u32>>, Vec<Option<Handle>>) {
    let mut batch = Vec::new();
    let mut expected = Vec::new();
    for (i, item) in fresh.iter().enumerate() {
        for _ in 0..1 + i % copies {
            batch.push(item.clone());
            expected.push(None);
        }
        if i % stored_every == 0 {
            batch.push(stored[i % stored.len()].clone());
            expected.push(Some(stored_handles[i % stored.len()]));
        }
    }
    let n = batch.len();
    let order: Vec<usize> = (0..n).map(|k| (k * 7919) % n).collect();
    assert_eq!(order.iter().collect::<HashSet<_>>().len(), n, "permutation");
    (
        order.iter().map(|&k| batch[k].clone()).collect(),
        order.iter().map(|&k| expected[k]).collect(),
    )
}

/// A mixed batch (single lanes, `hash::mixed`): one search-and-claim and one claimed insert
/// dispatch over four tables of different item sizes, the sizes' counts read on the GPU, a
/// bound above their sum: each distinct item is stored once in its table, equal items resolve
/// to one handle, stored items keep theirs; every variant. Large batches (two dispatches) and
/// batches one workgroup takes (both passes in one dispatch, a workgroup barrier between).
#[test]
fn mixed_batches_claim_and_insert_every_size_at_once() {
    let ctx = common::gpu();
    for variant in [
        HashVariant::Atomic64,
        HashVariant::TicketBoard,
        HashVariant::AccelHash32,
        HashVariant::AccelHash8,
    ] {
        check_mixed_batch(&ctx, variant, [150, 400, 100], false);
        check_mixed_batch(&ctx, variant, [8, 10, 2], true);
    }
}

/// One mixed batch of `variant` over four item sizes k = 0..3: per size `stored` items inserted
/// before and `fresh + step k` new ones (up to three copies each, stored ones mixed in);
/// `fused`: the batch is small enough for the one-dispatch pass, which the profiled pass names
/// must show.
fn check_mixed_batch(
    ctx: &Arc<GpuContext>,
    variant: HashVariant,
    [stored, fresh, step]: [usize; 3],
    fused: bool,
) {
    let ctx = ctx.clone();
    let sizes = [2u32, 3, 5, 9];
    let msg = format!("{variant:?}, {fresh} fresh items per size");
    let mut tables: Vec<GpuHashTable> = sizes
        .iter()
        .map(|&w| {
            let config = HashTableConfig {
                team: TeamMode::SingleLane,
                ..HashTableConfig::new(variant, w, 64)
            };
            GpuHashTable::new(&ctx, &config).unwrap()
        })
        .collect();
    let mixed = MixedPasses::new(&ctx, &tables[0]).unwrap();
    let mut taken = HashSet::new();
    // Per size: its batch (new items up to three times, stored ones mixed in, scattered)
    // and the handles its stored items had.
    let mut batches = Vec::new();
    let mut expected = Vec::new();
    for (k, &w) in sizes.iter().enumerate() {
        let stored = random_items(stored, w, 500 + w as u64, &mut taken);
        let (stored_handles, _) = tables[k].insert(&flat(&stored), None).unwrap();
        tables[k].reserve(2000).unwrap();
        let fresh = random_items(fresh + step * k, w, 900 + w as u64, &mut taken);
        let (batch, known) = repeated_batch(&fresh, &stored, &stored_handles, 3, 4);
        batches.push(batch);
        expected.push((known, stored.len() + fresh.len()));
    }
    let counts: Vec<u32> = (0..MIXED_SIZES)
        .map(|s| batches.get(s).map_or(0, |b| b.len() as u32))
        .collect();
    let bound = counts.iter().sum::<u32>() + 100;
    let buffers: Vec<_> = batches
        .iter()
        .zip(sizes)
        .map(|(batch, w)| {
            let n = batch.len() as u64;
            (
                ctx.upload("items", &flat(batch)).unwrap(),
                ctx.create_buffer("handles", 4 * n, MemLocation::GpuOnly)
                    .unwrap(),
                ctx.create_buffer("reps", 4 * n, MemLocation::GpuOnly)
                    .unwrap(),
                ClaimTable::new(&ctx, w, n as u32).unwrap(),
            )
        })
        .collect();
    let mut entries = [HashPush::default(); MIXED_SIZES];
    for (k, (items, handles, reps, claims)) in buffers.iter().enumerate() {
        let claims = Claims {
            table: claims,
            reps: reps.into(),
        };
        entries[k] = tables[k]
            .claimed_entry(items, handles, counts[k], claims)
            .unwrap();
    }
    let entry_buf = ctx.upload("entries", &entries).unwrap();
    let count_buf = ctx.upload("counts", &counts).unwrap();
    let mut cmd = ctx.begin_commands("mixed").unwrap();
    let before: Vec<_> = tables
        .iter()
        .map(|t| t.record_status(&mut cmd).unwrap())
        .collect();
    for (_, _, _, claims) in &buffers {
        claims.record_clear(&mut cmd).unwrap();
    }
    cmd.barrier();
    let mut profiler = Profiler::new(&ctx).unwrap();
    mixed
        .record(
            &mut cmd,
            &entry_buf,
            &count_buf,
            0,
            bound,
            Some(&mut profiler),
        )
        .unwrap();
    let after: Vec<_> = tables
        .iter()
        .map(|t| t.record_status(&mut cmd).unwrap())
        .collect();
    cmd.submit().unwrap();
    profiler.resolve().unwrap();
    if profiler.is_available() {
        let names: Vec<&str> = profiler.passes().iter().map(|p| p.name.as_str()).collect();
        let expected_names = match fused {
            true => vec!["hash search, claim and insert"],
            false => vec!["hash search and claim", "hash insert"],
        };
        assert_eq!(names, expected_names, "{msg}: bound {bound}");
    }
    drop(profiler);
    for (k, (before, after)) in before.into_iter().zip(after).enumerate() {
        let check = tables[k]
            .check_inserts(&before.read().unwrap()[0], after.read().unwrap()[0])
            .unwrap();
        assert_eq!(check, InsertCheck::default(), "{msg}: size {k}");
    }
    for (k, (_, handles, reps, _)) in buffers.iter().enumerate() {
        let handles: Vec<u32> = ctx.download(handles).unwrap();
        let reps: Vec<u32> = ctx.download(reps).unwrap();
        // A copy's handle is its representative's.
        let resolved: Vec<Handle> = handles
            .iter()
            .zip(&reps)
            .map(|(&h, &r)| {
                let h = if h == HANDLE_INVALID {
                    handles[r as usize]
                } else {
                    h
                };
                Handle::from_raw(h).expect("every item has a handle")
            })
            .collect();
        let (known, distinct) = &expected[k];
        let mut handle_of: HashMap<&Vec<u32>, Handle> = HashMap::new();
        for ((item, h), e) in batches[k].iter().zip(&resolved).zip(known) {
            if let Some(e) = e {
                assert_eq!(h, e, "{msg} size {k}: a stored item's handle changed");
            }
            assert_eq!(
                *handle_of.entry(item).or_insert(*h),
                *h,
                "{msg} size {k}: two handles"
            );
        }
        assert_eq!(
            tables[k].read_items(&resolved).unwrap(),
            flat(&batches[k]),
            "{msg} size {k}: read_items"
        );
        assert_eq!(
            walk_map(&tables[k].download().unwrap()).len(),
            *distinct,
            "{msg} size {k}"
        );
    }
}

/// The claim passes (single lanes): a find-or-insert whose batch repeats items stores each
/// distinct item once, equal items get one handle, stored items keep theirs; every variant,
/// small and large items, with and without pool exhaustion between the claim and the retry
/// rounds (then the owners a full pool left out are inserted by plain rounds).
#[test]
fn distinct_find_or_insert_stores_each_item_once() {
    let ctx = common::gpu();
    let cases = [
        (HashVariant::Atomic64, 1, true),
        (HashVariant::Atomic64, 9, true),
        (HashVariant::TicketBoard, 2, true),
        (HashVariant::AccelHash32, 10, true),
        (HashVariant::AccelHash8, 3, true),
        (HashVariant::AccelHash32, 2, false),
    ];
    for (variant, w, grow) in cases {
        let msg = format!("{variant:?} w={w} grow={grow}");
        let buckets = if grow { 13 } else { 24_000 };
        let config = HashTableConfig {
            team: TeamMode::SingleLane,
            grow_before_insert: grow,
            ..HashTableConfig::new(variant, w, buckets)
        };
        let mut gpu = GpuHashTable::new(&ctx, &config).unwrap();
        let mut cpu = ReferenceTable::new(variant, w, buckets).unwrap();
        let mut taken = HashSet::new();
        let stored = random_items(500, w, 31 + w as u64, &mut taken);
        let (stored_handles, _) = gpu.insert(&flat(&stored), None).unwrap();
        for item in &stored {
            cpu.insert(item).unwrap();
        }
        // New items up to 4 times each, spread over the batch, mixed with stored ones.
        let fresh = random_items(
            if grow { 3000 } else { 30_000 },
            w,
            77 + w as u64,
            &mut taken,
        );
        let (batch, expected) = repeated_batch(&fresh, &stored, &stored_handles, 4, 3);

        let (handles, report) = gpu.find_or_insert_distinct(&flat(&batch), None).unwrap();
        assert_eq!(report.rounds > 1, !grow, "{msg}: {report:?}");
        cpu.find_or_insert(&flat(&fresh)).unwrap();
        let mut handle_of: HashMap<&Vec<u32>, Handle> = HashMap::new();
        for ((item, h), e) in batch.iter().zip(&handles).zip(&expected) {
            if let Some(e) = e {
                assert_eq!(h, e, "{msg}: a stored item's handle changed");
            }
            assert_eq!(
                *handle_of.entry(item).or_insert(*h),
                *h,
                "{msg}: equal items, two handles"
            );
        }
        assert_eq!(
            gpu.read_items(&handles).unwrap(),
            flat(&batch),
            "{msg}: read_items"
        );
        // Each distinct item once, the reference's item set.
        let gpu_map = walk_map(&gpu.download().unwrap());
        let cpu_map = walk_map(cpu.image());
        assert_eq!(gpu_map.len(), stored.len() + fresh.len(), "{msg}");
        let gpu_items: HashSet<&Vec<u32>> = gpu_map.values().collect();
        let cpu_items: HashSet<&Vec<u32>> = cpu_map.values().collect();
        assert_eq!(gpu_items, cpu_items, "{msg}: item sets differ");
    }
    // The claim passes need single lanes.
    let subgroup = GpuHashTable::new(
        &ctx,
        &HashTableConfig {
            team: TeamMode::Subgroup,
            ..HashTableConfig::new(HashVariant::AccelHash32, 2, 4)
        },
    );
    match subgroup
        .unwrap()
        .find_or_insert_distinct(&[1, 2, 1, 2], None)
    {
        Err(HashError::InvalidArgument(m)) => assert!(m.contains("single-lane"), "{m}"),
        other => panic!("expected an error, got {other:?}"),
    }
    assert_clean(&ctx);
}

/// A table whose only bucket chain is corrupted on purpose: the last slab's link points back
/// to the first slab (`cycle`), or to a slab beyond the pool. Returns the items' handles too.
fn corrupted_table(
    ctx: &Arc<GpuContext>,
    variant: HashVariant,
    team: TeamMode,
    cycle: bool,
) -> (GpuHashTable, Vec<Handle>) {
    let config = HashTableConfig {
        team,
        ..HashTableConfig::new(variant, 2, 1)
    };
    let mut gpu = GpuHashTable::new(ctx, &config).unwrap();
    let items = random_items(100, 2, 7, &mut HashSet::new());
    let (handles, _) = gpu.insert(&flat(&items), None).unwrap();
    let image = gpu.download().unwrap();
    let layout = gpu.layout();
    // Follow the chain to its last slab (100 items: 4 slabs, all in super block 0).
    let mut link = image.heads[0];
    let mut last = link - 1;
    while link != 0 {
        last = link - 1;
        link = image.slab(last).unwrap()[0];
    }
    let next = if cycle { image.heads[0] } else { 0x7fff_ffff };
    let offset = 4 * (SUPER_BLOCK_BITMASK_WORDS as u64 + last as u64 * layout.slab_words as u64);
    ctx.write_buffer(&gpu.pool().super_blocks()[0], offset, &[next])
        .unwrap();
    (gpu, handles)
}

fn expect_corrupt<T: std::fmt::Debug>(what: &str, result: Result<T, HashError>) {
    match result {
        Err(HashError::CorruptTable { walks }) => assert!(walks > 0, "{what}"),
        other => panic!("{what}: expected CorruptTable, got {other:?}"),
    }
}

/// Every chain walk is bounded: a looping or out-of-pool chain makes search, insert and GC
/// report `CorruptTable` instead of hanging, in both team modes.
#[test]
fn corrupt_chains_are_reported_not_hung() {
    let ctx = common::gpu();
    let absent = random_items(64, 2, 8, &mut HashSet::new());
    for team in [TeamMode::SingleLane, TeamMode::Subgroup] {
        for variant in [HashVariant::Atomic64, HashVariant::AccelHash8] {
            for cycle in [true, false] {
                let what = format!("{variant:?} {team:?} cycle {cycle}");
                let (gpu, _) = corrupted_table(&ctx, variant, team, cycle);
                expect_corrupt(&format!("search {what}"), gpu.search(&flat(&absent), None));
                let (mut gpu, _) = corrupted_table(&ctx, variant, team, cycle);
                expect_corrupt(&format!("insert {what}"), gpu.insert(&flat(&absent), None));
                // Everything live: the sweep keeps every slab, so it walks the loop.
                let (mut gpu, live) = corrupted_table(&ctx, variant, team, cycle);
                let gc = GpuGarbageCollector::new(&ctx, &gpu).unwrap();
                expect_corrupt(&format!("gc {what}"), gc.collect(&mut gpu, &live, None));
            }
        }
    }
    assert_clean(&ctx);
}
