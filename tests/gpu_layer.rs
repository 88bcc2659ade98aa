//! The Vulkan layer on a real device (lavapipe in CI). Fails, not skips, without a device.
//! Every test ends with zero validation messages and zero live allocations.

use std::sync::Arc;

use voxdag::dag::{Svdag, VoxelIndex};
use voxdag::gpu::test_layouts::{FillPush, ImagePush};
use voxdag::gpu::{
    shaders, BindingKind, Bound, BufferSlice, ComputePipeline, ComputePipelineDesc, GpuContext,
    GpuError, GpuOptions, MemLocation, Profiler,
};
use voxdag::render::gpu::GpuRenderer;
use voxdag::render::{render_cpu, Camera, RenderOutput, RenderSettings};
use voxdag::scene::{morton, Voxels};

fn context() -> Arc<GpuContext> {
    let _ = env_logger::builder().is_test(true).try_init();
    let options = GpuOptions {
        validation: true,
        ..GpuOptions::default()
    };
    GpuContext::new(&options).expect("a Vulkan 1.2 device is required (lavapipe will do)")
}

/// Drops nothing itself: call after every resource is gone.
fn assert_clean(ctx: &Arc<GpuContext>) {
    // Deferred releases wait for the GPU: drain them first.
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.allocated_bytes(), 0);
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

/// Push constants of `shaders/glsl/test/fill.comp`.
/// The test fill shader with specialization constants `[workgroup size, multiplier]`.
fn fill_pipeline(ctx: &Arc<GpuContext>, name: &str, spec: [u32; 2]) -> ComputePipeline {
    ctx.create_compute_pipeline(&ComputePipelineDesc {
        name,
        spirv: shaders::TEST_FILL,
        spec_constants: &spec,
        push_constant_size: std::mem::size_of::<FillPush>() as u32,
        bindings: &[],
    })
    .unwrap()
}

fn fill_push(out: u64, aux: u64, count: u32, seed: u32) -> Vec<u8> {
    bytemuck::bytes_of(&FillPush {
        out_addr: out,
        aux_addr: aux,
        count,
        seed,
    })
    .to_vec()
}

#[test]
fn device_creation_reports_info() {
    let ctx = context();
    let info = ctx.info().clone();
    println!("{info:#?}");
    assert!(!info.name.is_empty());
    assert!(info.api_version >= (1, 2, 0));
    assert!(
        info.subgroup_size.is_power_of_two(),
        "{}",
        info.subgroup_size
    );
    assert!(info.max_storage_buffer_range >= 1 << 27);
    assert!(info.max_memory_allocation_size >= 1 << 30);
    assert!(info.max_compute_workgroup_invocations >= 128);
    assert!(info.timestamp_period > 0.0);
    assert!(
        ctx.validation_enabled(),
        "VK_LAYER_KHRONOS_validation should be installed"
    );
    assert_clean(&ctx);
}

#[test]
fn device_override_that_matches_nothing_lists_devices() {
    let _ = env_logger::builder().is_test(true).try_init();
    let options = GpuOptions {
        validation: false,
        device: Some("no such gpu 1234".into()),
        ..GpuOptions::default()
    };
    match GpuContext::new(&options) {
        Err(GpuError::DeviceNotFound { wanted, available }) => {
            assert_eq!(wanted, "no such gpu 1234");
            assert!(!available.is_empty() && available != "none", "{available}");
        }
        Err(e) => panic!("unexpected error {e}"),
        Ok(_) => panic!("a device matched a nonsense name"),
    }
}

#[test]
fn buffer_round_trip_and_range_errors() {
    let ctx = context();
    {
        let data: Vec<u32> = (0..100_003u32)
            .map(|i| i.wrapping_mul(2_654_435_761))
            .collect();
        let buf = ctx.upload("round trip", &data).unwrap();
        assert_eq!(buf.size(), 400_012);
        assert_ne!(buf.address(), 0);
        assert_eq!(ctx.download::<u32>(&buf).unwrap(), data);
        // Partial write and read at an offset.
        ctx.write_buffer(&buf, 40, &[7u32, 8, 9]).unwrap();
        assert_eq!(
            ctx.read_buffer::<u32>(&buf, 36, 5).unwrap(),
            vec![data[9], 7, 8, 9, data[13]]
        );
        // Out of range, zero and too large sizes are errors, not panics.
        assert!(matches!(
            ctx.read_buffer::<u32>(&buf, 400_000, 4),
            Err(GpuError::OutOfRange { .. })
        ));
        assert!(matches!(
            ctx.write_buffer(&buf, u64::MAX - 2, &[1u32]),
            Err(GpuError::OutOfRange { .. })
        ));
        assert!(ctx.create_buffer("empty", 0, MemLocation::GpuOnly).is_err());
        let too_big = ctx.info().max_memory_allocation_size + 1;
        match ctx.create_buffer("huge", too_big, MemLocation::GpuOnly) {
            Err(GpuError::TooLarge { name, size, .. }) => {
                assert_eq!(name, "huge");
                assert_eq!(size, too_big);
            }
            other => panic!("expected TooLarge, got {other:?}"),
        }
        // A range fill changes exactly its words; unaligned or outside ranges are errors.
        let mut cmd = ctx.begin_commands("fill range").unwrap();
        cmd.fill_range(&buf, 8, 12, 0xabcd).unwrap();
        assert!(matches!(
            cmd.fill_range(&buf, 400_008, 8, 0),
            Err(GpuError::OutOfRange { .. })
        ));
        assert!(cmd.fill_range(&buf, 2, 4, 0).is_err());
        assert!(cmd.fill_range(&buf, 4, 6, 0).is_err());
        // A slice names its bytes by address; its fill changes only them.
        let slice = buf.slice(400, 8).unwrap();
        assert_eq!(slice.address(), buf.address() + 400);
        assert_eq!(
            (slice.offset(), slice.size(), slice.name()),
            (400, 8, "round trip")
        );
        assert!(matches!(
            buf.slice(400_008, 8),
            Err(GpuError::OutOfRange { .. })
        ));
        assert_eq!(BufferSlice::from(&buf).size(), buf.size());
        cmd.fill_slice(slice, 0x5151).unwrap();
        cmd.submit().unwrap();
        assert_eq!(
            ctx.read_buffer::<u32>(&buf, 4, 5).unwrap(),
            vec![data[1], 0xabcd, 0xabcd, 0xabcd, data[5]]
        );
        assert_eq!(
            ctx.read_buffer::<u32>(&buf, 396, 4).unwrap(),
            vec![data[99], 0x5151, 0x5151, data[102]]
        );
        // Host-visible buffers are written and read through their mapping.
        let mut host = ctx
            .create_buffer("host", 16, MemLocation::CpuToGpu)
            .unwrap();
        ctx.write_mapped(&mut host, 4, &[5u32, 6]).unwrap();
        assert_eq!(ctx.download::<u32>(&host).unwrap()[1..3], [5, 6]);
        assert_eq!(ctx.live_allocations(), 2);
    }
    assert_clean(&ctx);
}

#[test]
fn dropped_small_buffers_are_reused_with_their_own_size() {
    let ctx = context();
    {
        let first = ctx
            .create_buffer("first", 1000, MemLocation::GpuOnly)
            .unwrap();
        let address = first.address();
        drop(first);
        ctx.wait_idle().unwrap();
        // The same size class (1024 bytes) and location: the same Vulkan buffer, seen with the
        // new size; fills, uploads and downloads stay within it.
        let second = ctx
            .create_buffer("second", 700, MemLocation::GpuOnly)
            .unwrap();
        assert_eq!(second.address(), address);
        assert_eq!(second.size(), 700);
        let data: Vec<u32> = (0..175u32).map(|i| i * 3 + 1).collect();
        ctx.write_buffer(&second, 0, &data).unwrap();
        assert_eq!(ctx.download::<u32>(&second).unwrap(), data);
        let mut cmd = ctx.begin_commands("fill").unwrap();
        cmd.fill_buffer(&second, 9);
        cmd.submit().unwrap();
        assert_eq!(ctx.download::<u32>(&second).unwrap(), vec![9u32; 175]);
        // Another class or location gets a buffer of its own; a host-visible one maps its size.
        let other_class = ctx
            .create_buffer("other", 3000, MemLocation::GpuOnly)
            .unwrap();
        assert_ne!(other_class.address(), address);
        let mut host = ctx
            .create_buffer("host", 12, MemLocation::CpuToGpu)
            .unwrap();
        ctx.write_mapped(&mut host, 0, &[1u32, 2, 3]).unwrap();
        assert!(ctx.write_mapped(&mut host, 12, &[4u32]).is_err());
        assert_eq!(ctx.download::<u32>(&host).unwrap(), [1, 2, 3]);
        // Counted as live while used, not once dropped (kept buffers are released for counting).
        assert_eq!(ctx.live_allocations(), 3);
    }
    assert_clean(&ctx);
}

#[test]
fn fill_shader_spec_and_push_constants_and_subgroup_size() {
    let ctx = context();
    {
        let count = 10_007u32;
        let out = ctx
            .create_buffer("fill out", count as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let aux = ctx
            .create_buffer("fill aux", count as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let subgroup = ctx.info().subgroup_size;
        // Two specializations of the same shader: workgroup size and multiplier differ.
        for (wg, mul, seed) in [(64u32, 3u32, 11u32), (subgroup, 1_000_003, 0xdead_beef)] {
            let pipeline = fill_pipeline(&ctx, "test fill", [wg, mul]);
            let mut cmd = ctx.begin_commands("fill").unwrap();
            cmd.fill_buffer(&out, 0);
            // Fewer groups than needed: the shader's grid-stride loop covers the rest.
            let groups = (count / wg / 3).max(1);
            let push = fill_push(out.address(), aux.address(), count, seed);
            cmd.dispatch(&pipeline, [groups, 1, 1], &push, &[]).unwrap();
            // Wrong push-constant size is rejected.
            assert!(cmd
                .dispatch(&pipeline, [1, 1, 1], &push[..16], &[])
                .is_err());
            cmd.submit().unwrap();
            let got = ctx.download::<u32>(&out).unwrap();
            let want: Vec<u32> = (0..count)
                .map(|i| i.wrapping_mul(mul).wrapping_add(seed))
                .collect();
            assert_eq!(got, want, "workgroup {wg}, multiplier {mul}");
            let sizes = ctx.download::<u32>(&aux).unwrap();
            assert!(
                sizes.iter().all(|&s| s == subgroup),
                "gl_SubgroupSize != {subgroup}"
            );
        }
    }
    assert_clean(&ctx);
}

/// `Commands::warm` dispatches zero workgroups: it writes nothing, and it is the pipeline's first
/// dispatch (where llvmpipe compiles), so the real dispatch after it is not; a zero-group
/// `dispatch` records no dispatch at all and counts nothing.
#[test]
fn warm_up_runs_nothing_and_is_the_first_dispatch() {
    let ctx = context();
    {
        let count = 1000u32;
        let out = ctx
            .create_buffer("warm out", count as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let pipeline = fill_pipeline(&ctx, "test fill warm", [64, 7]);
        let push = fill_push(out.address(), 0, count, 5);
        let first = ctx.first_dispatches();
        let mut cmd = ctx.begin_commands("zero groups").unwrap();
        cmd.fill_buffer(&out, 0);
        cmd.dispatch(&pipeline, [0, 1, 1], &push, &[]).unwrap();
        cmd.submit().unwrap();
        assert_eq!(ctx.first_dispatches(), first, "a zero-group dispatch");
        let mut cmd = ctx.begin_commands("warm").unwrap();
        cmd.warm(&pipeline, &[]).unwrap();
        cmd.warm(&pipeline, &[]).unwrap();
        cmd.submit().unwrap();
        assert_eq!(ctx.first_dispatches(), first + 1);
        assert!(ctx.download::<u32>(&out).unwrap().iter().all(|&w| w == 0));
        let mut cmd = ctx.begin_commands("fill").unwrap();
        cmd.dispatch(&pipeline, [4, 1, 1], &push, &[]).unwrap();
        cmd.submit().unwrap();
        assert_eq!(ctx.first_dispatches(), first + 1, "warmed already");
        let want: Vec<u32> = (0..count).map(|i| i * 7 + 5).collect();
        assert_eq!(ctx.download::<u32>(&out).unwrap(), want);
        // A pipeline first dispatched for real counts once too.
        let other = fill_pipeline(&ctx, "test fill cold", [64, 9]);
        let mut cmd = ctx.begin_commands("cold").unwrap();
        cmd.dispatch(&other, [4, 1, 1], &push, &[]).unwrap();
        cmd.dispatch(&other, [4, 1, 1], &push, &[]).unwrap();
        cmd.submit().unwrap();
        assert_eq!(ctx.first_dispatches(), first + 2);
    }
    assert_clean(&ctx);
}

/// Transfers in a row that touch different bytes share one barrier; one that reads or writes
/// bytes another wrote since the last barrier, and any dispatch after transfers, gets a barrier
/// first (`Commands::before_transfer`). Synchronization validation (on in these tests) reports
/// a hazard wherever a needed barrier is missing, and the values read back show the order.
#[test]
fn transfers_share_barriers_unless_they_touch_the_same_bytes() {
    let ctx = context();
    {
        let pipeline = fill_pipeline(&ctx, "test fill", [64, 3]);
        let make = |name| ctx.create_buffer(name, 64, MemLocation::GpuOnly).unwrap();
        let (a, b, c) = (make("a"), make("b"), make("c"));
        let mut cmd = ctx.begin_commands("transfers").unwrap();
        let start = cmd.barriers_recorded();
        assert_eq!(start, 1, "a recording starts with one barrier");
        // Distinct buffers, or distinct bytes of one: no barrier between.
        cmd.fill_buffer(&a, 7);
        cmd.upload(&b, 0, &[1u32; 16]).unwrap();
        cmd.fill_range(&c, 0, 32, 9).unwrap();
        cmd.fill_range(&c, 32, 32, 10).unwrap();
        assert_eq!(cmd.barriers_recorded(), start);
        // A write over bytes written since the barrier.
        cmd.upload(&a, 8, &[5u32, 6]).unwrap();
        assert_eq!(cmd.barriers_recorded(), start + 1);
        // A read of bytes written (a), a write over bytes written (c[4..8]).
        cmd.copy_buffer(&a, 0, &c, 16, 16).unwrap();
        assert_eq!(cmd.barriers_recorded(), start + 2);
        let read_c = cmd.readback::<u32>(&c, 0, 16).unwrap();
        assert_eq!(cmd.barriers_recorded(), start + 3);
        // A dispatch after transfers, a transfer after a dispatch.
        let push = fill_push(b.address(), 0, 16, 100);
        cmd.dispatch(&pipeline, [1, 1, 1], &push, &[]).unwrap();
        assert_eq!(cmd.barriers_recorded(), start + 4);
        let read_b = cmd.readback::<u32>(&b, 0, 16).unwrap();
        assert_eq!(cmd.barriers_recorded(), start + 5);
        // Reads of bytes only read since the barrier: none.
        let read_a = cmd.readback::<u32>(&a, 0, 16).unwrap();
        assert_eq!(cmd.barriers_recorded(), start + 5);
        // Two barriers in a row record one.
        cmd.barrier();
        cmd.barrier();
        assert_eq!(cmd.barriers_recorded(), start + 6);
        cmd.submit().unwrap();
        let mut want_a = vec![7u32; 16];
        want_a[2..4].copy_from_slice(&[5, 6]);
        assert_eq!(read_a.read().unwrap(), want_a);
        let mut want_c = vec![9u32; 8];
        want_c.extend([10u32; 8]);
        want_c[4..8].copy_from_slice(&want_a[..4]);
        assert_eq!(read_c.read().unwrap(), want_c);
        let want_b: Vec<u32> = (0..16).map(|i| i * 3 + 100).collect();
        assert_eq!(read_b.read().unwrap(), want_b);
    }
    assert_clean(&ctx);
}

/// Several threads record and submit at once on one shared context (each `Commands` must own
/// what Vulkan requires to be externally synchronised); every result is checked exactly.
#[test]
fn commands_record_and_submit_from_several_threads_at_once() {
    let ctx = context();
    {
        let pipeline = fill_pipeline(&ctx, "test fill threads", [64, 7]);
        let (threads, submissions) = (4u32, 10u32);
        let start = std::sync::Barrier::new(threads as usize);
        std::thread::scope(|s| {
            for t in 0..threads {
                let (ctx, pipeline, start) = (&ctx, &pipeline, &start);
                s.spawn(move || {
                    // Different sizes per thread so that mixed-up results cannot match.
                    let count = 40_000 + 1_013 * t;
                    let out = ctx
                        .create_buffer(
                            &format!("thread {t}"),
                            count as u64 * 4,
                            MemLocation::GpuOnly,
                        )
                        .unwrap();
                    start.wait();
                    for i in 0..submissions {
                        let seed = t * 1_000 + i;
                        let mut cmd = ctx.begin_commands(&format!("thread {t} #{i}")).unwrap();
                        cmd.fill_buffer(&out, 0xffff_ffff);
                        cmd.dispatch(
                            pipeline,
                            [8 + t, 1, 1],
                            &fill_push(out.address(), 0, count, seed),
                            &[],
                        )
                        .unwrap();
                        cmd.submit().unwrap();
                        let got = ctx.download::<u32>(&out).unwrap();
                        let bad = (0..count)
                            .position(|j| got[j as usize] != j.wrapping_mul(7).wrapping_add(seed));
                        assert_eq!(bad, None, "thread {t}, submission {i}: first wrong word");
                    }
                });
            }
        });
    }
    assert_clean(&ctx);
}

#[test]
fn buffer_larger_than_max_storage_range_via_device_address() {
    let ctx = context();
    {
        let range = ctx.info().max_storage_buffer_range as u64;
        // 160 MiB, or more than the range on devices where it is larger than 128 MiB; where
        // no buffer may pass the range (NVIDIA: 4 GiB - 1 against allocations of at most
        // 4 GiB - 2 MiB), the largest allocation, still reached through its address.
        let largest = ctx.info().max_memory_allocation_size & !3;
        let bytes = (160u64 << 20).max(range + (32 << 20)).min(largest);
        let count = (bytes / 4) as u32;
        let big = ctx
            .create_buffer("big", bytes, MemLocation::GpuOnly)
            .unwrap();
        let pipeline = fill_pipeline(&ctx, "test fill big", [256, 5]);
        let mut cmd = ctx.begin_commands("fill big").unwrap();
        cmd.dispatch(
            &pipeline,
            [1024, 1, 1],
            &fill_push(big.address(), 0, count, 1),
            &[],
        )
        .unwrap();
        cmd.submit().unwrap();
        let got = ctx.download::<u32>(&big).unwrap();
        assert_eq!(got.len(), count as usize);
        let bad = got
            .iter()
            .enumerate()
            .position(|(i, &v)| v != (i as u32).wrapping_mul(5).wrapping_add(1));
        assert_eq!(bad, None, "first wrong word");
        // The tail beyond maxStorageBufferRange was written too.
        let tail = ctx.read_buffer::<u32>(&big, bytes - 8, 2).unwrap();
        assert_eq!(tail, vec![(count - 2) * 5 + 1, (count - 1) * 5 + 1]);
    }
    assert_clean(&ctx);
}

#[test]
fn storage_image_readback() {
    let ctx = context();
    {
        let (w, h, seed) = (37u32, 23u32, 9u32);
        let image = ctx.create_storage_image("test image", w, h).unwrap();
        let pipeline = ctx
            .create_compute_pipeline(&ComputePipelineDesc {
                name: "test image",
                spirv: shaders::TEST_IMAGE,
                spec_constants: &[],
                push_constant_size: std::mem::size_of::<ImagePush>() as u32,
                bindings: &[BindingKind::StorageImage],
            })
            .unwrap();
        // A fresh image reads back as zeros.
        assert!(ctx.read_image(&image).unwrap().iter().all(|&b| b == 0));
        let mut cmd = ctx.begin_commands("image").unwrap();
        let push = bytemuck::bytes_of(&ImagePush {
            width: w,
            height: h,
            seed,
        })
        .to_vec();
        assert!(
            cmd.dispatch(&pipeline, [1, 1, 1], &push, &[]).is_err(),
            "image missing"
        );
        cmd.dispatch(
            &pipeline,
            [w.div_ceil(8), h.div_ceil(8), 1],
            &push,
            &[Bound::Image(&image)],
        )
        .unwrap();
        cmd.submit().unwrap();
        let rgba = ctx.read_image(&image).unwrap();
        assert_eq!(rgba.len(), (w * h * 4) as usize);
        for y in 0..h {
            for x in 0..w {
                let i = ((y * w + x) * 4) as usize;
                let want = [x as u8, y as u8, (x + y + seed) as u8, 255];
                assert_eq!(rgba[i..i + 4], want, "pixel ({x}, {y})");
            }
        }
        assert!(ctx.create_storage_image("zero", 0, 4).is_err());
    }
    assert_clean(&ctx);
}

/// A uniform texel buffer of word pairs reads back exactly at scattered indices; dispatches
/// whose resources do not match the pipeline's bindings, texel buffers of no texels and
/// pipelines with more bindings of a kind than the descriptor pools hold are refused.
#[test]
fn texel_buffer_fetches_word_pairs() {
    let ctx = context();
    {
        // 7919 is prime, so i -> i * 7919 % count visits every texel once.
        let (count, seed) = (5000u32, 3u32);
        let pairs: Vec<[u32; 2]> = (0..count)
            .map(|i| [i.wrapping_mul(0x9e37_79b9), !i])
            .collect();
        let texels = ctx.upload_texels("test texels", &pairs).unwrap();
        assert_eq!(texels.texels(), count as u64);
        let out = ctx
            .create_buffer("texels out", 8 * count as u64, MemLocation::GpuOnly)
            .unwrap();
        let pipeline = ctx
            .create_compute_pipeline(&ComputePipelineDesc {
                name: "test texels",
                spirv: shaders::TEST_TEXELS,
                spec_constants: &[],
                push_constant_size: std::mem::size_of::<FillPush>() as u32,
                bindings: &[BindingKind::TexelBuffer],
            })
            .unwrap();
        let push = fill_push(out.address(), 0, count, seed);
        let image = ctx.create_storage_image("wrong binding", 4, 4).unwrap();
        let mut cmd = ctx.begin_commands("texels").unwrap();
        for wrong in [&[][..], &[Bound::Image(&image)][..]] {
            let e = cmd
                .dispatch(&pipeline, [1, 1, 1], &push, wrong)
                .unwrap_err();
            assert!(e.to_string().contains("TexelBuffer"), "{e}");
        }
        cmd.dispatch(&pipeline, [8, 1, 1], &push, &[Bound::Texels(&texels)])
            .unwrap();
        cmd.submit().unwrap();
        let got = ctx.download::<u32>(&out).unwrap();
        let want: Vec<u32> = pairs.iter().flatten().map(|w| w + seed).collect();
        let bad = (0..got.len()).position(|i| got[i] != want[i]);
        assert_eq!(bad, None, "first wrong word");
        assert!(ctx.upload_texels("none", &[]).is_err());
        // A word view of any buffer: texel k is (word k, 0).
        let words: Vec<u32> = pairs.iter().map(|p| p[0]).collect();
        let word_buffer = ctx.upload("test words", &words).unwrap();
        let word_view = ctx.word_texels(&word_buffer).unwrap();
        assert_eq!(word_view.texels(), count as u64);
        let mut cmd = ctx.begin_commands("word texels").unwrap();
        cmd.dispatch(&pipeline, [8, 1, 1], &push, &[Bound::Words(&word_view)])
            .unwrap();
        cmd.submit().unwrap();
        let got = ctx.download::<u32>(&out).unwrap();
        let want: Vec<u32> = words.iter().flat_map(|&w| [w + seed, seed]).collect();
        let bad = (0..got.len()).position(|i| got[i] != want[i]);
        assert_eq!(bad, None, "first wrong word of the word view");
        let too_many = ctx.create_compute_pipeline(&ComputePipelineDesc {
            name: "six texel buffers",
            spirv: shaders::TEST_TEXELS,
            spec_constants: &[],
            push_constant_size: std::mem::size_of::<FillPush>() as u32,
            bindings: &[BindingKind::TexelBuffer; 6],
        });
        assert!(too_many.is_err());
    }
    assert_clean(&ctx);
}

#[test]
fn profiler_times_each_pass_and_writes_a_trace() {
    let ctx = context();
    {
        let mut profiler = Profiler::new(&ctx).unwrap();
        assert!(profiler.is_available(), "lavapipe supports timestamps");
        let count = 1 << 20;
        let out = ctx
            .create_buffer("profiled", count as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let pipeline = fill_pipeline(&ctx, "test fill", [64, 1]);
        let push = fill_push(out.address(), 0, count, 0);
        for frame in 0..2 {
            let mut cmd = ctx.begin_commands("profiled").unwrap();
            profiler.begin_pass(&mut cmd, "clear");
            cmd.fill_buffer(&out, 0);
            profiler.end_pass(&mut cmd);
            profiler.begin_pass(&mut cmd, "fill");
            cmd.dispatch(&pipeline, [256, 1, 1], &push, &[]).unwrap();
            profiler.end_pass(&mut cmd);
            // The GPU work happens between the start of the submit and the end of resolve, and
            // resolve places it on the CPU clock: the passes must lie inside that wall-clock span.
            let start = std::time::Instant::now();
            cmd.submit().unwrap();
            let timings = profiler.resolve().unwrap();
            profiler.record_cpu_span("submit+resolve", start, std::time::Instant::now());
            let span = profiler.cpu_spans().last().unwrap().clone();
            let names: Vec<&str> = timings.iter().map(|t| t.name.as_str()).collect();
            assert_eq!(names, ["clear", "fill"], "frame {frame}");
            // Clock alignment is exact up to rounding (both clocks are monotonic nanoseconds).
            let eps = 1e-3;
            for t in &timings {
                // Clearing and filling 4 MiB each take measurable time.
                assert!(t.gpu_ms > 0.0, "{t:?}");
                assert!(t.gpu_ms <= span.dur_ms, "{t:?} longer than {span:?}");
                assert!(
                    t.cpu_start_ms + eps >= span.start_ms,
                    "{t:?} before {span:?}"
                );
                assert!(
                    t.cpu_start_ms + t.gpu_ms <= span.start_ms + span.dur_ms + eps,
                    "{t:?} ends after {span:?}"
                );
            }
            // Recorded in this order, so "fill" starts after "clear" started.
            assert!(
                timings[1].cpu_start_ms >= timings[0].cpu_start_ms,
                "{timings:?}"
            );
        }
        let _ = profiler
            .cpu_span("readback", || ctx.download::<u32>(&out))
            .unwrap();
        assert_eq!(profiler.passes().len(), 4);
        let table = profiler.table();
        println!("{table}");
        let fill_row = table.lines().find(|l| l.starts_with("gpu: fill")).unwrap();
        assert_eq!(fill_row.split_whitespace().nth(2), Some("2"), "{fill_row}");
        assert!(table.contains("cpu: readback"));
        let submit_row = table
            .lines()
            .find(|l| l.starts_with("cpu: submit+resolve"))
            .unwrap();
        assert_eq!(
            submit_row.split_whitespace().nth(2),
            Some("2"),
            "{submit_row}"
        );

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("trace.json");
        profiler.write_chrome_trace(&path).unwrap();
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let events = json["traceEvents"].as_array().unwrap();
        let complete: Vec<&serde_json::Value> = events.iter().filter(|e| e["ph"] == "X").collect();
        assert_eq!(complete.len(), 4 + 3);
        for e in &complete {
            assert_eq!(e["pid"], 1);
        }
        let (gpu, cpu): (Vec<&serde_json::Value>, Vec<&serde_json::Value>) =
            complete.iter().partition(|e| e["tid"] == 1);
        assert!(cpu.iter().all(|e| e["tid"] == 2));
        // The events carry the profiler's passes and spans, in µs (ms * 1000).
        let micros = |e: &serde_json::Value, k: &str| e[k].as_f64().unwrap();
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1.0);
        assert_eq!(gpu.len(), profiler.passes().len());
        for (e, p) in gpu.iter().zip(profiler.passes()) {
            assert_eq!(e["name"], p.name.as_str());
            assert!(close(micros(e, "ts"), p.cpu_start_ms * 1e3), "{e} vs {p:?}");
            assert!(close(micros(e, "dur"), p.gpu_ms * 1e3), "{e} vs {p:?}");
        }
        let cpu_names: Vec<&str> = cpu.iter().map(|e| e["name"].as_str().unwrap()).collect();
        assert_eq!(cpu_names, ["submit+resolve", "submit+resolve", "readback"]);
        for (e, s) in cpu.iter().zip(profiler.cpu_spans()) {
            assert!(close(micros(e, "ts"), s.start_ms * 1e3), "{e} vs {s:?}");
            assert!(close(micros(e, "dur"), s.dur_ms * 1e3), "{e} vs {s:?}");
        }
        // Frame k's two GPU passes lie inside its submit+resolve span; the spans follow each
        // other, and the readback comes after both.
        for (k, frame) in gpu.chunks(2).enumerate() {
            let (s0, s1) = (
                micros(cpu[k], "ts"),
                micros(cpu[k], "ts") + micros(cpu[k], "dur"),
            );
            for e in frame {
                let (t0, t1) = (micros(e, "ts"), micros(e, "ts") + micros(e, "dur"));
                assert!(t0 + 1.0 >= s0 && t1 <= s1 + 1.0, "{e} outside {}", cpu[k]);
            }
        }
        assert!(micros(cpu[1], "ts") >= micros(cpu[0], "ts") + micros(cpu[0], "dur"));
        assert!(micros(cpu[2], "ts") >= micros(cpu[1], "ts") + micros(cpu[1], "dur"));
        // Resolving with a pass still open is an error, not a hang.
        let mut cmd = ctx.begin_commands("unbalanced").unwrap();
        profiler.begin_pass(&mut cmd, "open");
        assert!(profiler.resolve().is_err());
        profiler.end_pass(&mut cmd);
        cmd.submit().unwrap();
        assert_eq!(profiler.resolve().unwrap().len(), 1);
    }
    assert_clean(&ctx);
}

/// Passes in a command buffer dropped without a submit (an error path) are discarded, open or
/// closed, and do not block later passes; a closed pass not yet submitted is a recoverable error.
#[test]
fn profiler_recovers_from_command_buffers_dropped_unsubmitted() {
    let ctx = context();
    {
        let mut profiler = Profiler::new(&ctx).unwrap();
        let count = 1 << 16;
        let out = ctx
            .create_buffer("profiled", count as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let pipeline = fill_pipeline(&ctx, "test fill", [64, 1]);
        let push = fill_push(out.address(), 0, count, 3);
        // A pass left open, plus a closed one, in a command buffer that is never submitted.
        {
            let mut cmd = ctx.begin_commands("abandoned").unwrap();
            profiler.begin_pass(&mut cmd, "closed, never submitted");
            cmd.fill_buffer(&out, 0);
            profiler.end_pass(&mut cmd);
            profiler.begin_pass(&mut cmd, "open, never submitted");
            cmd.dispatch(&pipeline, [16, 1, 1], &push, &[]).unwrap();
        }
        for round in 0..2 {
            let mut cmd = ctx.begin_commands("normal").unwrap();
            profiler.begin_pass(&mut cmd, "fill");
            cmd.dispatch(&pipeline, [16, 1, 1], &push, &[]).unwrap();
            profiler.end_pass(&mut cmd);
            // Closed but not yet submitted: an error that keeps the pass.
            assert!(profiler.resolve().is_err(), "round {round}");
            cmd.submit().unwrap();
            let timings = profiler.resolve().unwrap();
            let names: Vec<&str> = timings.iter().map(|t| t.name.as_str()).collect();
            assert_eq!(names, ["fill"], "round {round}");
            assert!(timings[0].gpu_ms > 0.0, "{timings:?}");
        }
        // The submitted fills ran.
        let got = ctx.download::<u32>(&out).unwrap();
        assert!((0..count).all(|i| got[i as usize] == i + 3));
        assert_eq!(profiler.passes().len(), 2);
    }
    assert_clean(&ctx);
}

/// A floor, a sphere and a few pillars in a `n^3` grid, optionally with colours.
fn test_scene(n: u32, colored: bool) -> Voxels {
    let mut coords = Vec::new();
    let c = n as f32 / 2.0;
    let r = n as f32 * 0.3;
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let (fx, fy, fz) = (
                    x as f32 + 0.5 - c,
                    y as f32 + 0.5 - c * 0.9,
                    z as f32 + 0.5 - c,
                );
                let sphere = fx * fx + fy * fy + fz * fz <= r * r;
                let floor = y < 2;
                let pillar = (x % 16 == 3 && z % 16 == 5) && y < n / 2;
                if sphere || floor || pillar {
                    coords.push([x, y, z]);
                }
            }
        }
    }
    let mut codes: Vec<u64> = coords
        .iter()
        .map(|c| morton::encode(c[0], c[1], c[2]))
        .collect();
    codes.sort_unstable();
    let colors = if colored {
        codes
            .iter()
            .map(|&m| {
                let [x, y, z] = morton::decode(m);
                0xff00_0000 | (x * 4) | ((y * 4) << 8) | (((x ^ z) & 0xff) << 16)
            })
            .collect()
    } else {
        Vec::new()
    };
    Voxels {
        resolution: n,
        codes,
        colors,
    }
}

/// Pixels whose hit flags differ, and the largest / mean colour channel difference over pixels
/// that both renderers hit or both missed.
fn compare(cpu: &RenderOutput, gpu: &RenderOutput) -> (usize, u8, f64) {
    assert_eq!((cpu.width, cpu.height), (gpu.width, gpu.height));
    assert_eq!(gpu.rgba.len(), cpu.rgba.len());
    assert_eq!(gpu.hits.len(), cpu.hits.len());
    assert!(gpu.hits.iter().all(|&h| h <= 1));
    let mut hit_diff = 0;
    let (mut max, mut sum, mut n) = (0u8, 0u64, 0u64);
    for i in 0..cpu.hits.len() {
        if cpu.hits[i] != gpu.hits[i] {
            hit_diff += 1;
            continue;
        }
        for k in 0..4 {
            let d = cpu.rgba[i * 4 + k].abs_diff(gpu.rgba[i * 4 + k]);
            max = max.max(d);
            sum += d as u64;
            n += 1;
        }
    }
    (hit_diff, max, sum as f64 / n.max(1) as f64)
}

#[test]
fn gpu_render_matches_cpu_reference() {
    let ctx = context();
    {
        let renderer = GpuRenderer::new(&ctx).unwrap();
        let mut profiler = Profiler::new(&ctx).unwrap();
        let n = 64;
        for colored in [false, true] {
            let dag = Svdag::from_voxels(&test_scene(n, colored)).unwrap();
            let index = VoxelIndex::new(&dag);
            let scene = renderer.upload(&dag).unwrap();
            assert_eq!(scene.color_count() as usize, dag.colors.len());
            let mut inside = Camera::orbit_default(n);
            inside.eye = [5.5, 20.25, 60.75];
            inside.target = [32.0, 25.0, 30.0];
            for (camera, shadows) in [(Camera::orbit_default(n), true), (inside, false)] {
                let mut settings = RenderSettings::new(161, 97, camera);
                settings.shadows = shadows;
                let cpu = render_cpu(&dag, &index, &settings).unwrap();
                let gpu = renderer
                    .render(&scene, &settings, Some(&mut profiler))
                    .unwrap();
                let (hit_diff, max, mean) = compare(&cpu, &gpu);
                let pixels = cpu.hits.len();
                println!(
                    "colored {colored} shadows {shadows}: {} hits, {hit_diff} hit flags differ, \
                     colour diff max {max} mean {mean:.4}",
                    cpu.hit_count()
                );
                assert!(
                    cpu.hit_count() > pixels / 10,
                    "the scene should fill the view"
                );
                assert!(
                    hit_diff * 1000 <= pixels,
                    "{hit_diff} of {pixels} hit flags differ"
                );
                assert!(mean <= 0.05, "mean channel difference {mean}");
                assert!(max <= 2, "max channel difference {max}");
            }
        }
        let timings: Vec<&str> = profiler.passes().iter().map(|p| p.name.as_str()).collect();
        assert_eq!(timings, ["primary rays"; 4]);
        println!("{}", profiler.table());
    }
    assert_clean(&ctx);
}

#[test]
fn gpu_render_of_empty_scene_is_all_sky() {
    let ctx = context();
    {
        let renderer = GpuRenderer::new(&ctx).unwrap();
        let dag = Svdag::from_voxels(&Voxels {
            resolution: 8,
            ..Voxels::default()
        })
        .unwrap();
        let index = VoxelIndex::new(&dag);
        let scene = renderer.upload(&dag).unwrap();
        let settings = RenderSettings::new(20, 12, Camera::orbit_default(8));
        let gpu = renderer.render(&scene, &settings, None).unwrap();
        let cpu = render_cpu(&dag, &index, &settings).unwrap();
        assert!(gpu.hits.iter().all(|&h| h == 0));
        let (hit_diff, max, _) = compare(&cpu, &gpu);
        assert_eq!(
            (hit_diff, max <= 1),
            (0, true),
            "max channel difference {max}"
        );
        // Bad settings are errors, not panics.
        let bad = RenderSettings::new(0, 12, Camera::orbit_default(8));
        assert!(renderer.render(&scene, &bad, None).is_err());
    }
    assert_clean(&ctx);
}
