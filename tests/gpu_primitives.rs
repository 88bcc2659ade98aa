//! GPU primitives (`voxdag::compute`) against their CPU references, exactly: exclusive scan,
//! stream compaction (+ an indirect dispatch sized by it) and the key/value radix sort, at the
//! sizes around the subgroup, the block and powers of two up to 2^26, and at every subgroup size
//! lavapipe can be forced to (child processes with `LP_NATIVE_VECTOR_WIDTH`). Fails, not
//! skips, without a Vulkan device. Every test ends with zero validation messages and zero live
//! allocations.

mod common;

use std::process::Command;
use std::sync::Arc;

use common::Rng;
use voxdag::compute::{reference, PrimitiveOptions, Primitives, COUNT_ARGS_BYTES, GRID_X};
use voxdag::gpu::test_layouts::IndirectConsumePush;
use voxdag::gpu::{shaders, ComputePipelineDesc, GpuContext, GpuError, MemLocation, Profiler};

/// Set in the child processes: the subgroup size the child must see.
const CHILD_ENV: &str = "VOXDAG_PRIMITIVES_EXPECT_SUBGROUP";

fn context() -> Arc<GpuContext> {
    let _ = env_logger::builder().is_test(true).try_init();
    common::gpu()
}

/// Call after every resource is gone.
fn assert_clean(ctx: &Arc<GpuContext>) {
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

/// 0, 1, subgroup - 1, subgroup, subgroup + 1, and 2^k - 1, 2^k, 2^k + 1 for k in `ks`.
fn sizes(subgroup: u32, ks: impl IntoIterator<Item = u32>) -> Vec<usize> {
    let s = subgroup as usize;
    let mut v = vec![0, 1, s - 1, s, s + 1];
    for k in ks {
        v.extend([(1usize << k) - 1, 1 << k, (1 << k) + 1]);
    }
    v.sort_unstable();
    v.dedup();
    v
}

fn random_words(rng: &mut Rng, n: usize) -> Vec<u32> {
    (0..n).map(|_| rng.next() as u32).collect()
}

fn check_scan(prims: &Primitives, data: &[u32], what: &str) {
    let got = prims.exclusive_scan(data, None).unwrap();
    let want = reference::exclusive_scan(data);
    assert!(got == want, "scan of {} {what} words differs", data.len());
}

fn check_compact(prims: &Primitives, rng: &mut Rng, n: usize, keep_percent: u64) {
    let values: Vec<u32> = (0..n as u32).map(|i| i ^ 0x5a5a_0000).collect();
    // Flags are arbitrary words: only zero / non-zero matters.
    let flags: Vec<u32> = (0..n)
        .map(|_| {
            if rng.below(100) < keep_percent {
                (rng.next() as u32) | 1
            } else {
                0
            }
        })
        .collect();
    let group = 64;
    let (kept, args) = prims.compact(&values, &flags, group, None).unwrap();
    let want = reference::compact(&values, &flags);
    assert!(
        kept == want,
        "compaction of {n} ({keep_percent}% kept) differs"
    );
    assert_eq!(args, reference::indirect_args(want.len() as u32, group));
}

/// Key patterns for the sorts: random, all equal, sorted, reverse sorted, only high bits set,
/// and few distinct keys (long runs of equal keys: stability).
fn key_patterns(rng: &mut Rng, n: usize, bits: u32) -> Vec<(&'static str, Vec<u64>)> {
    let mask = if bits == 64 {
        u64::MAX
    } else {
        (1 << bits) - 1
    };
    let random: Vec<u64> = (0..n).map(|_| rng.next() & mask).collect();
    let mut sorted = random.clone();
    sorted.sort_unstable();
    let reverse: Vec<u64> = sorted.iter().rev().copied().collect();
    vec![
        ("random", random),
        ("all equal", vec![0x1234_5678_9abc_def0 & mask; n]),
        ("sorted", sorted),
        ("reverse sorted", reverse),
        (
            "high bits only",
            (0..n).map(|_| rng.next() << (bits - 4) & mask).collect(),
        ),
        (
            "few distinct",
            (0..n).map(|_| rng.below(3) << (bits - 2) | 7).collect(),
        ),
    ]
}

/// Sorts (keys, value = index) on the GPU and compares with the stable CPU sort.
fn check_sort(prims: &Primitives, keys: &[u64], bits: u32, what: &str) {
    let values: Vec<u32> = (0..keys.len() as u32).collect();
    if bits == 32 {
        let k32: Vec<u32> = keys.iter().map(|&k| k as u32).collect();
        let got = prims.sort_u32(&k32, &values, None).unwrap();
        let want = reference::sort_pairs(&k32, &values);
        assert!(
            got == want,
            "u32 sort of {} {what} keys differs",
            keys.len()
        );
    } else {
        let got = prims.sort_u64(keys, &values, None).unwrap();
        let want = reference::sort_pairs(keys, &values);
        assert!(
            got == want,
            "u64 sort of {} {what} keys differs",
            keys.len()
        );
    }
}

/// Scan, compaction and both sorts at the sizes that matter for `subgroup` up to 2^`max_k`,
/// with the default tuning and a tiny block (32 elements) that makes the scan four levels deep.
fn all_primitives_small(ctx: &Arc<GpuContext>, max_k: u32) {
    let subgroup = ctx.info().subgroup_size;
    let mut rng = Rng(subgroup as u64);
    // 8-bit digits: the per-bit split sort (the default is 4-bit counting ranks).
    let tiny = PrimitiveOptions {
        workgroup: 16,
        items: 2,
        radix_bits: 8,
    };
    for prims in [
        Primitives::new(ctx).unwrap(),
        Primitives::with_options(ctx, tiny).unwrap(),
    ] {
        for n in sizes(subgroup, 1..=max_k) {
            let data = random_words(&mut rng, n);
            check_scan(&prims, &data, "random");
            check_compact(&prims, &mut rng, n, 50);
            for (what, keys) in key_patterns(&mut rng, n, 32) {
                check_sort(&prims, &keys, 32, what);
            }
            let keys = key_patterns(&mut rng, n, 64).swap_remove(0).1;
            check_sort(&prims, &keys, 64, "random");
        }
    }
}

#[test]
fn scan_matches_cpu_up_to_2_pow_26() {
    let ctx = context();
    {
        let prims = Primitives::new(&ctx).unwrap();
        let subgroup = ctx.info().subgroup_size;
        let mut rng = Rng(1);
        for n in sizes(subgroup, 1..=20) {
            check_scan(&prims, &random_words(&mut rng, n), "random");
            let small: Vec<u32> = (0..n).map(|_| rng.below(4) as u32).collect();
            check_scan(&prims, &small, "small");
        }
        // 2^22 + 1 and 2^26 + 1 need two and three levels of partial sums with 2048-element
        // blocks; 2^26 words (256 MiB) is far beyond maxStorageBufferRange (device addresses).
        for n in [(1 << 22) - 1, (1 << 22) + 1, 1 << 24, (1 << 26) + 1] {
            check_scan(&prims, &random_words(&mut rng, n), "random");
        }
    }
    assert_clean(&ctx);
}

#[test]
fn scan_records_into_a_callers_commands_with_profiled_passes() {
    let ctx = context();
    {
        let prims = Primitives::new(&ctx).unwrap();
        let mut profiler = Profiler::new(&ctx).unwrap();
        let mut rng = Rng(2);
        let n = (1usize << 22) + 3;
        let data = random_words(&mut rng, n);
        let input = ctx.upload("input", &data).unwrap();
        let total = ctx.create_buffer("total", 4, MemLocation::GpuOnly).unwrap();
        let scratch = prims.scan_scratch(n as u64).unwrap();
        let mut cmd = ctx.begin_commands("caller").unwrap();
        // In place, twice in one command buffer: the second scan sees the first's result.
        for _ in 0..2 {
            prims
                .record_exclusive_scan(
                    &mut cmd,
                    &input,
                    &input,
                    &total,
                    n as u64,
                    &scratch,
                    Some(&mut profiler),
                )
                .unwrap();
        }
        cmd.submit().unwrap();
        let (once, _) = reference::exclusive_scan(&data);
        let (twice, total_twice) = reference::exclusive_scan(&once);
        assert!(ctx.download::<u32>(&input).unwrap() == twice);
        assert_eq!(ctx.download::<u32>(&total).unwrap(), vec![total_twice]);
        let passes = profiler.resolve().unwrap();
        let names: Vec<&str> = passes.iter().map(|p| p.name.as_str()).collect();
        let one = [
            "scan reduce L0",
            "scan reduce L1",
            "scan block L2",
            "scan block L1",
            "scan block L0",
        ];
        assert_eq!(names, [one, one].concat());
        assert!(passes.iter().all(|p| p.gpu_ms > 0.0), "{passes:?}");
        // Too small a scratch and too short an output are errors, not GPU faults.
        let small = prims.scan_scratch(10).unwrap();
        let mut cmd = ctx.begin_commands("bad").unwrap();
        let err = prims.record_exclusive_scan(&mut cmd, &input, &input, &total, 11, &small, None);
        assert!(matches!(err, Err(GpuError::InvalidArgument(_))), "{err:?}");
        let err =
            prims.record_exclusive_scan(&mut cmd, &input, &total, &total, n as u64, &scratch, None);
        assert!(matches!(err, Err(GpuError::InvalidArgument(_))), "{err:?}");
        drop(cmd);
    }
    assert_clean(&ctx);
}

#[test]
fn compaction_matches_cpu_up_to_2_pow_26() {
    let ctx = context();
    {
        let prims = Primitives::new(&ctx).unwrap();
        let subgroup = ctx.info().subgroup_size;
        let mut rng = Rng(3);
        for n in sizes(subgroup, 1..=16) {
            for keep in [0, 3, 50, 100] {
                check_compact(&prims, &mut rng, n, keep);
            }
        }
        for n in [(1 << 18) - 1, (1 << 20) + 1, (1 << 22) - 1, 1 << 26] {
            check_compact(&prims, &mut rng, n, 50);
        }
    }
    assert_clean(&ctx);
}

/// Compaction writes the survivor count and indirect arguments on the GPU; a second pass in
/// the same command buffer is dispatched indirectly over exactly the survivors (with 1-wide
/// workgroups the grid needs y > 1: more than 65535 workgroups).
#[test]
fn compaction_sizes_an_indirect_dispatch_over_exactly_the_survivors() {
    let ctx = context();
    {
        let prims = Primitives::new(&ctx).unwrap();
        let mut rng = Rng(4);
        for (n, keep, group) in [(1000usize, 37u64, 64u32), (3, 0, 64), (140_000, 98, 1)] {
            let values = random_words(&mut rng, n);
            let flags: Vec<u32> = (0..n).map(|_| (rng.below(100) < keep) as u32).collect();
            let consume = ctx
                .create_compute_pipeline(&ComputePipelineDesc {
                    name: "indirect consume",
                    spirv: shaders::TEST_INDIRECT_CONSUME,
                    spec_constants: &[group],
                    push_constant_size: std::mem::size_of::<IndirectConsumePush>() as u32,
                    bindings: &[],
                })
                .unwrap();
            let v = ctx.upload("values", &values).unwrap();
            let f = ctx.upload("flags", &flags).unwrap();
            let survivors = ctx
                .create_buffer("survivors", n as u64 * 4, MemLocation::GpuOnly)
                .unwrap();
            let count_args = ctx
                .create_buffer("count args", COUNT_ARGS_BYTES, MemLocation::GpuOnly)
                .unwrap();
            let out = ctx
                .create_buffer("consumed", n as u64 * 4, MemLocation::GpuOnly)
                .unwrap();
            let stats = ctx.upload("stats", &[0u32, 0]).unwrap();
            let scratch = prims.scan_scratch(n as u64).unwrap();
            let mut cmd = ctx.begin_commands("compact + indirect").unwrap();
            cmd.fill_buffer(&out, u32::MAX);
            prims
                .record_compact(
                    &mut cmd,
                    &v,
                    &f,
                    n as u64,
                    &survivors,
                    &count_args,
                    group,
                    &scratch,
                    None,
                )
                .unwrap();
            let push = bytemuck::bytes_of(&IndirectConsumePush {
                count_args: count_args.address(),
                input_words: survivors.address(),
                output_words: out.address(),
                stats: stats.address(),
            })
            .to_vec();
            cmd.dispatch_indirect(&consume, &count_args, 4, &push, &[])
                .unwrap();
            cmd.submit().unwrap();

            let want = reference::compact(&values, &flags);
            let count = want.len();
            let args = reference::indirect_args(count as u32, group);
            let got_args = ctx.download::<u32>(&count_args).unwrap();
            assert_eq!(got_args, [&[count as u32][..], &args[..]].concat());
            if group == 1 {
                assert!(args[1] > 1 && args[0] == GRID_X, "{args:?}: a 2D grid");
            }
            let launched = args[0] as u64 * args[1] as u64 * group as u64;
            let stats = ctx.download::<u32>(&stats).unwrap();
            assert_eq!(stats, [launched as u32, count as u32], "invocations");
            let consumed = ctx.download::<u32>(&out).unwrap();
            let expect: Vec<u32> = want
                .iter()
                .map(|x| x.wrapping_mul(3).wrapping_add(1))
                .chain(std::iter::repeat(u32::MAX))
                .take(n)
                .collect();
            assert!(consumed == expect, "indirect pass over {count} survivors");
        }
    }
    assert_clean(&ctx);
}

#[test]
fn dispatch_indirect_checks_its_arguments() {
    let ctx = context();
    {
        let pipeline = ctx
            .create_compute_pipeline(&ComputePipelineDesc {
                name: "indirect consume",
                spirv: shaders::TEST_INDIRECT_CONSUME,
                spec_constants: &[64],
                push_constant_size: std::mem::size_of::<IndirectConsumePush>() as u32,
                bindings: &[],
            })
            .unwrap();
        let args = ctx.upload("args", &[0u32, 0, 1, 1]).unwrap();
        let push = [0u8; 32];
        let mut cmd = ctx.begin_commands("bad indirect").unwrap();
        for (offset, push_len) in [
            (2u64, 32usize),
            (8, 32),
            (16, 32),
            (u64::MAX - 3, 32),
            (4, 16),
        ] {
            let err = cmd.dispatch_indirect(&pipeline, &args, offset, &push[..push_len], &[]);
            assert!(
                matches!(err, Err(GpuError::InvalidArgument(_))),
                "offset {offset}, {push_len} push bytes: {err:?}"
            );
        }
        // A zero workgroup count dispatches nothing and is valid.
        cmd.dispatch_indirect(&pipeline, &args, 0, &[0u8; 32], &[])
            .unwrap();
        cmd.submit().unwrap();
    }
    assert_clean(&ctx);
}

#[test]
fn sort_u32_matches_cpu_and_is_stable() {
    let ctx = context();
    {
        let prims = Primitives::new(&ctx).unwrap();
        let subgroup = ctx.info().subgroup_size;
        let mut rng = Rng(5);
        for n in sizes(subgroup, 1..=16) {
            for (what, keys) in key_patterns(&mut rng, n, 32) {
                check_sort(&prims, &keys, 32, what);
            }
        }
        // 2^20 keys: 512 tiles, a 2^13-entry histogram (4-bit digits) scanned over two levels.
        for n in [(1 << 18) + 1, (1 << 20) + 1] {
            for (what, keys) in key_patterns(&mut rng, n, 32)
                .into_iter()
                .filter(|(w, _)| ["random", "few distinct"].contains(w))
            {
                check_sort(&prims, &keys, 32, what);
            }
        }
        for n in large_sort_sizes() {
            for width in [32, 64] {
                let mask = if width == 64 {
                    u64::MAX
                } else {
                    u64::from(u32::MAX)
                };
                let keys: Vec<u64> = (0..n).map(|_| rng.next() & mask).collect();
                check_sort(&prims, &keys, width, "random");
            }
        }
    }
    assert_clean(&ctx);
}

/// Sizes past 2^20 for the sorts, from `VOXDAG_TEST_SORT_LOG2=K` (2^K - 1 and 2^K + 1 random
/// keys of both widths; K up to 26). Not run by default: a 2^22 sort takes 12-30 s on lavapipe
/// with 2 cores, 2^26 minutes (docs/gpu-primitives.md).
fn large_sort_sizes() -> Vec<usize> {
    match std::env::var("VOXDAG_TEST_SORT_LOG2") {
        Ok(k) => {
            let k: u32 = k.trim().parse().expect("VOXDAG_TEST_SORT_LOG2: a number");
            assert!(
                (21..=26).contains(&k),
                "VOXDAG_TEST_SORT_LOG2 must be 21..=26"
            );
            vec![(1 << k) - 1, (1 << k) + 1]
        }
        Err(_) => Vec::new(),
    }
}

#[test]
fn sort_u64_matches_cpu_and_is_stable() {
    let ctx = context();
    {
        let prims = Primitives::new(&ctx).unwrap();
        let subgroup = ctx.info().subgroup_size;
        let mut rng = Rng(6);
        for n in sizes(subgroup, 1..=14) {
            for (what, keys) in key_patterns(&mut rng, n, 64) {
                check_sort(&prims, &keys, 64, what);
            }
        }
        for (n, patterns) in [
            ((1 << 17) + 1, &["random", "high bits only"][..]),
            ((1 << 20) - 1, &["random"][..]),
        ] {
            for (what, keys) in key_patterns(&mut rng, n, 64)
                .into_iter()
                .filter(|(w, _)| patterns.contains(w))
            {
                check_sort(&prims, &keys, 64, what);
            }
        }
    }
    assert_clean(&ctx);
}

#[test]
fn sort_with_8_bit_digits_matches_cpu() {
    let ctx = context();
    {
        let options = PrimitiveOptions {
            radix_bits: 8,
            ..PrimitiveOptions::default()
        };
        let prims = Primitives::with_options(&ctx, options).unwrap();
        let mut rng = Rng(7);
        for n in [0, 1, 2047, 2048, 2049, 20_001] {
            for bits in [32, 64] {
                for (what, keys) in key_patterns(&mut rng, n, bits) {
                    check_sort(&prims, &keys, bits, what);
                }
            }
        }
        // Bad tuning is an error.
        let bad = PrimitiveOptions {
            radix_bits: 5,
            ..options
        };
        assert!(Primitives::with_options(&ctx, bad).is_err());
    }
    assert_clean(&ctx);
}

/// Every primitive at this process's subgroup size (as a child of
/// `primitives_at_every_forced_subgroup_size`, it first checks that it sees the forced size,
/// in the device info and in `gl_SubgroupSize`).
#[test]
fn primitives_at_this_subgroup_size() {
    let ctx = context();
    let subgroup = ctx.info().subgroup_size;
    {
        let fill = ctx
            .create_compute_pipeline(&ComputePipelineDesc {
                name: "test fill",
                spirv: shaders::TEST_FILL,
                spec_constants: &[64, 1],
                push_constant_size: 24,
                bindings: &[],
            })
            .unwrap();
        let out = ctx
            .create_buffer("fill out", 256 * 4, MemLocation::GpuOnly)
            .unwrap();
        let aux = ctx
            .create_buffer("fill aux", 256 * 4, MemLocation::GpuOnly)
            .unwrap();
        let mut push = Vec::new();
        push.extend_from_slice(&out.address().to_le_bytes());
        push.extend_from_slice(&aux.address().to_le_bytes());
        push.extend_from_slice(&256u32.to_le_bytes());
        push.extend_from_slice(&0u32.to_le_bytes());
        let mut cmd = ctx.begin_commands("subgroup size").unwrap();
        cmd.dispatch(&fill, [4, 1, 1], &push, &[]).unwrap();
        cmd.submit().unwrap();
        let seen = ctx.download::<u32>(&aux).unwrap();
        assert!(
            seen.iter().all(|&s| s == subgroup),
            "{seen:?} vs {subgroup}"
        );
    }
    if let Ok(expected) = std::env::var(CHILD_ENV) {
        assert_eq!(subgroup.to_string(), expected, "forced subgroup size");
    }
    all_primitives_small(&ctx, 12);
    println!("subgroup size {subgroup}: all primitives match their CPU references");
    assert_clean(&ctx);
}

/// lavapipe's subgroup size follows `LP_NATIVE_VECTOR_WIDTH` (bits / 32 lanes), read when the
/// driver loads: each size runs `primitives_at_this_subgroup_size` in a child process.
#[test]
fn primitives_at_every_forced_subgroup_size() {
    let ctx = context();
    let on_lavapipe = ctx.info().driver_name.contains("llvmpipe");
    let native = ctx.info().subgroup_size;
    assert_clean(&ctx);
    drop(ctx);
    let forced: Vec<(Option<u32>, u32)> = if on_lavapipe {
        [128, 256, 512].map(|w| (Some(w), w / 32)).to_vec()
    } else {
        // Other drivers cannot be forced: check the native size in a child all the same.
        vec![(None, native)]
    };
    let exe = std::env::current_exe().unwrap();
    for (width, expected) in forced {
        let mut child = Command::new(&exe);
        child
            .args([
                "--exact",
                "primitives_at_this_subgroup_size",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD_ENV, expected.to_string());
        if let Some(w) = width {
            child.env("LP_NATIVE_VECTOR_WIDTH", w.to_string());
        }
        let out = child.output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "child at LP_NATIVE_VECTOR_WIDTH={width:?} failed:\n{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let marker = format!("subgroup size {expected}: all primitives match their CPU references");
        assert!(stdout.contains(&marker), "child did not run: {stdout}");
        assert!(stdout.contains("1 passed"), "{stdout}");
    }
}
