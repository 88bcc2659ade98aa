//! The real-time GPU layer on a real device (lavapipe in CI, validation and synchronization
//! validation on): dependent pass chains in one submission, the timeline, frames in flight with
//! deferred release, staging rings, growing descriptor pools, capability refusal, error mapping,
//! and the submissions / host waits each operation costs. Fails, not skips, without a device.

mod common;

use std::collections::VecDeque;
use std::sync::Arc;

use ash::vk;
use voxdag::attr::lossless::LosslessVariant;
use voxdag::attr_gpu::lossless::LosslessGpu;
use voxdag::gpu::test_layouts::{ChainPush, FillPush, ImagePush};
use voxdag::gpu::{
    shaders, BindingKind, Bound, ComputePipeline, ComputePipelineDesc, FrameRing, GpuContext,
    GpuError, GpuOptions, GpuStats, MemLocation, Readback, REQUIRED_FEATURES,
};
use voxdag::hash::dedup::GpuDedup;
use voxdag::hash::gc::GpuGarbageCollector;
use voxdag::hash::{GpuHashTable, HashTableConfig, HashVariant};

/// Drains deferred releases, then checks: no validation message, no live allocation.
fn assert_clean(ctx: &Arc<GpuContext>) {
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.allocated_bytes(), 0);
    assert_eq!(ctx.pending_releases(), 0);
}

const _: () = assert!(std::mem::size_of::<ChainPush>() == std::mem::size_of::<FillPush>());

fn pipeline(ctx: &Arc<GpuContext>, name: &str, spirv: &[u32], spec: &[u32]) -> ComputePipeline {
    ctx.create_compute_pipeline(&ComputePipelineDesc {
        name,
        spirv,
        spec_constants: spec,
        // Shared by `test/chain.comp` and `test/fill.comp`, whose push blocks have the same size.
        push_constant_size: std::mem::size_of::<ChainPush>() as u32,
        bindings: &[],
    })
    .unwrap()
}

/// CPU reference of `test/chain.comp`'s pass `p`.
fn chain_cpu(src: &[u32], p: u32) -> Vec<u32> {
    let n = src.len();
    (0..n)
        .map(|i| {
            src[(i + 1) % n]
                .wrapping_mul(31)
                .wrapping_add(p)
                .wrapping_add(i as u32)
        })
        .collect()
}

#[test]
fn a_chain_of_1000_dependent_passes_in_one_submission_matches_the_cpu() {
    let ctx = common::gpu();
    {
        let chain = pipeline(&ctx, "test chain", shaders::TEST_CHAIN, &[64]);
        let n = 3_001u32;
        let passes = 1_000u32;
        let init: Vec<u32> = (0..n).map(|i| i.wrapping_mul(2_654_435_761)).collect();
        let a = ctx
            .create_buffer("chain a", n as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let b = ctx
            .create_buffer("chain b", n as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let before = ctx.stats();
        let mut cmd = ctx.begin_commands("chain").unwrap();
        cmd.upload(&a, 0, &init).unwrap();
        for p in 0..passes {
            let (src, dst) = if p % 2 == 0 { (&a, &b) } else { (&b, &a) };
            cmd.dispatch(
                &chain,
                [n.div_ceil(64), 1, 1],
                bytemuck::bytes_of(&ChainPush {
                    src_addr: src.address(),
                    dst_addr: dst.address(),
                    count: n,
                    pass_index: p,
                }),
                &[],
            )
            .unwrap();
            cmd.barrier();
        }
        let last = if passes.is_multiple_of(2) { &a } else { &b };
        let back: Readback<u32> = cmd.readback(last, 0, n as usize).unwrap();
        let submission = cmd.submit_async().unwrap();
        assert_eq!(submission.value(), ctx.last_submitted());
        let got = back.read().unwrap();
        assert!(submission.is_done().unwrap());
        assert!(ctx.completed_value().unwrap() >= submission.value());
        let cost = ctx.stats().since(before);
        assert_eq!(
            cost,
            GpuStats {
                submissions: 1,
                host_waits: 1
            }
        );
        let mut want = init;
        for p in 0..passes {
            want = chain_cpu(&want, p);
        }
        let bad = (0..n as usize).position(|i| got[i] != want[i]);
        assert_eq!(bad, None, "first wrong word after {passes} passes");
        // Waiting for a value never submitted is an error, not a hang.
        assert!(ctx.wait_for(ctx.last_submitted() + 1).is_err());
    }
    assert_clean(&ctx);
}

#[test]
fn deferred_release_1000_frames_with_3_in_flight() {
    let ctx = common::gpu();
    {
        let fill = pipeline(&ctx, "test fill frames", shaders::TEST_FILL, &[64, 3]);
        let frames = 1_000u32;
        let results = ctx
            .create_buffer("frame results", frames as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let mut ring = FrameRing::new(&ctx, 3).unwrap();
        assert!(FrameRing::new(&ctx, 0).is_err());
        // Counters read back a frame late through the readback ring: (frame, readback).
        let mut late: VecDeque<(u32, Readback<u32>)> = VecDeque::new();
        let mut peak_bytes = 0u64;
        let mut peak_pending = 0usize;
        let base_bytes = ctx.allocated_bytes();
        let before = ctx.stats();
        for f in 0..frames {
            ring.begin_frame().unwrap();
            // Whatever is 3 frames old has completed: no wait.
            while late.front().is_some_and(|(g, _)| g + 3 <= f) {
                let (g, back) = late.pop_front().unwrap();
                let words = back.read().unwrap();
                assert_eq!(words, vec![5 * 3 + g, 6 * 3 + g], "frame {g} readback");
            }
            // A buffer per frame, of varying size, dropped right after its submission.
            let count = 1_024 + 97 * (f % 13);
            let buf = ctx
                .create_buffer(
                    &format!("frame {f}"),
                    count as u64 * 4,
                    MemLocation::GpuOnly,
                )
                .unwrap();
            let mut cmd = ctx.begin_commands("frame").unwrap();
            cmd.dispatch(
                &fill,
                [count.div_ceil(64), 1, 1],
                bytemuck::bytes_of(&FillPush {
                    out_addr: buf.address(),
                    aux_addr: 0,
                    count,
                    seed: f,
                }),
                &[],
            )
            .unwrap();
            cmd.copy_buffer(&buf, 0, &results, f as u64 * 4, 4).unwrap();
            late.push_back((f, cmd.readback(&buf, 20, 2).unwrap()));
            let submission = cmd.submit_async().unwrap();
            ring.end_frame(&submission);
            drop(buf);
            peak_bytes = peak_bytes.max(ctx.allocated_bytes() - base_bytes);
            peak_pending = peak_pending.max(ctx.pending_releases());
        }
        ring.wait_all().unwrap();
        for (g, back) in late {
            assert_eq!(back.read().unwrap(), vec![5 * 3 + g, 6 * 3 + g]);
        }
        let cost = ctx.stats().since(before);
        println!(
            "1000 frames: {cost:?}, peak {peak_bytes} bytes and {peak_pending} pending releases"
        );
        // Frame f filled buf[0] = f before the copy: no buffer was freed while in use.
        let got: Vec<u32> = ctx.download(&results).unwrap();
        assert_eq!(got, (0..frames).collect::<Vec<_>>());
        // Memory stays flat: at most the frames in flight (+ the one being recorded) hold a
        // buffer, each at most (1024 + 97 * 12) words.
        let largest = (1_024 + 97 * 12) * 4u64;
        assert!(peak_bytes <= 5 * largest, "peak {peak_bytes} bytes");
        assert!(
            peak_pending <= 5 * 3,
            "peak {peak_pending} pending releases"
        );
        assert_eq!(cost.submissions, frames as u64);
        // begin_frame waits at most once per frame.
        assert!(cost.host_waits <= frames as u64, "{cost:?}");
    }
    assert_clean(&ctx);
}

#[test]
fn more_than_64_image_dispatches_in_one_recording() {
    let ctx = common::gpu();
    {
        let (w, h) = (19u32, 11u32);
        let images: Vec<_> = (0..3)
            .map(|i| ctx.create_storage_image(&format!("img {i}"), w, h).unwrap())
            .collect();
        let pipeline = ctx
            .create_compute_pipeline(&ComputePipelineDesc {
                name: "test image",
                spirv: shaders::TEST_IMAGE,
                spec_constants: &[],
                push_constant_size: std::mem::size_of::<ImagePush>() as u32,
                bindings: &[BindingKind::StorageImage],
            })
            .unwrap();
        let dispatches = 300u32;
        let mut cmd = ctx.begin_commands("many image sets").unwrap();
        for d in 0..dispatches {
            let push = bytemuck::bytes_of(&ImagePush {
                width: w,
                height: h,
                seed: d,
            })
            .to_vec();
            let image = &images[(d % 3) as usize];
            cmd.dispatch(
                &pipeline,
                [w.div_ceil(8), h.div_ceil(8), 1],
                &push,
                &[Bound::Image(image)],
            )
            .unwrap();
            cmd.barrier();
        }
        assert!(
            cmd.descriptor_pool_count() >= 2,
            "the pool should have grown"
        );
        cmd.submit().unwrap();
        for (i, image) in images.iter().enumerate() {
            // The last dispatch into image i had seed d = the largest d < 300 with d % 3 == i.
            let seed = (0..dispatches).filter(|d| d % 3 == i as u32).max().unwrap();
            let rgba = ctx.read_image(image).unwrap();
            for y in 0..h {
                for x in 0..w {
                    let p = ((y * w + x) * 4) as usize;
                    let want = [x as u8, y as u8, (x + y + seed) as u8, 255];
                    assert_eq!(rgba[p..p + 4], want, "image {i} pixel ({x}, {y})");
                }
            }
        }
    }
    assert_clean(&ctx);
}

#[test]
fn a_device_missing_a_required_feature_is_refused_by_name() {
    common::gpu(); // sets up XDG_RUNTIME_DIR; the device exists
    for &feature in REQUIRED_FEATURES {
        let options = GpuOptions {
            validation: false,
            mask_features: vec![feature.to_string()],
            ..GpuOptions::default()
        };
        match GpuContext::new(&options) {
            Err(GpuError::Unsupported { feature: f, device }) => {
                assert_eq!(f, feature);
                assert!(!device.is_empty());
                let message = GpuError::Unsupported { feature: f, device }.to_string();
                assert!(message.contains(feature), "{message}");
            }
            Err(e) => panic!("masking {feature}: unexpected error {e}"),
            Ok(_) => panic!("masking {feature}: the device was accepted"),
        }
    }
}

#[test]
fn vulkan_and_allocator_errors_map_to_actionable_kinds() {
    use vk::Result as R;
    assert!(matches!(
        GpuError::from_vk("vkQueueSubmit", R::ERROR_DEVICE_LOST),
        GpuError::DeviceLost
    ));
    assert!(matches!(
        GpuError::from_vk("vkAllocateMemory", R::ERROR_OUT_OF_DEVICE_MEMORY),
        GpuError::OutOfDeviceMemory(_)
    ));
    assert!(matches!(
        GpuError::from_vk("vkCreateBuffer", R::ERROR_OUT_OF_HOST_MEMORY),
        GpuError::OutOfHostMemory(_)
    ));
    assert!(matches!(
        GpuError::from_vk("vkAcquireNextImageKHR", R::ERROR_OUT_OF_DATE_KHR),
        GpuError::OutOfDate
    ));
    assert!(matches!(
        GpuError::from_vk("vkQueuePresentKHR", R::ERROR_SURFACE_LOST_KHR),
        GpuError::SurfaceLost
    ));
    match GpuError::from_vk("vkCreateComputePipelines", R::ERROR_UNKNOWN) {
        GpuError::Vulkan { call, result } => {
            assert_eq!(call, "vkCreateComputePipelines");
            assert_eq!(result, R::ERROR_UNKNOWN);
        }
        e => panic!("unexpected {e:?}"),
    }
    use gpu_allocator::AllocationError as A;
    assert!(matches!(
        GpuError::from_allocation("big", A::OutOfMemory),
        GpuError::OutOfDeviceMemory(_)
    ));
    assert!(matches!(
        GpuError::from_allocation(
            "big",
            A::Internal("Unexpected error in vkAllocateMemory: ERROR_OUT_OF_HOST_MEMORY".into())
        ),
        GpuError::OutOfHostMemory(_)
    ));
    assert!(matches!(
        GpuError::from_allocation("x", A::NoCompatibleMemoryTypeFound),
        GpuError::Allocation { .. }
    ));
}

/// Submissions and host waits per host-level operation on the recorded layer (printed for
/// docs/gpu.md; the hash operations are pinned).
#[test]
fn submissions_and_host_waits_per_operation() {
    let ctx = common::gpu();
    {
        let mut table =
            GpuHashTable::new(&ctx, &HashTableConfig::new(HashVariant::AccelHash32, 2, 64))
                .unwrap();
        let items: Vec<u32> = (1..=2_000u32).flat_map(|i| [i, i * 7]).collect();
        let mut rows = Vec::new();
        let mut measure = |name: &str, f: &mut dyn FnMut()| {
            ctx.wait_idle().unwrap();
            let before = ctx.stats();
            f();
            let cost = ctx.stats().since(before);
            rows.push((name.to_string(), cost));
            cost
        };
        let one = GpuStats {
            submissions: 1,
            host_waits: 1,
        };
        let mut handles = Vec::new();
        let c = measure("hash find_or_insert (host items)", &mut || {
            handles = table.find_or_insert(&items, None).unwrap().0;
        });
        assert_eq!(c, one);
        let c = measure("hash find_or_insert, all present", &mut || {
            assert_eq!(table.find_or_insert(&items, None).unwrap().0, handles);
        });
        assert_eq!(c, one);
        let c = measure("hash search (host items)", &mut || {
            let found = table.search(&items, None).unwrap();
            assert!(found.iter().all(Option::is_some));
        });
        assert_eq!(c, one);
        let c = measure("hash read_items", &mut || {
            assert_eq!(table.read_items(&handles).unwrap(), items);
        });
        assert_eq!(c, one);
        let gc = GpuGarbageCollector::new(&ctx, &table).unwrap();
        let c = measure("hash gc collect (host handles)", &mut || {
            gc.collect(&mut table, &handles[..1_000], None).unwrap();
        });
        assert_eq!(c, one);
        let dedup = GpuDedup::new(&ctx, 2).unwrap();
        let values: Vec<u32> = (0..2_000).collect();
        let c = measure("dedup (host keys)", &mut || {
            dedup.dedup(&items, &values, None).unwrap();
        });
        assert_eq!(c, one);
        let lossless = LosslessGpu::new(&ctx).unwrap();
        // RGB888 keeps alpha 255.
        let colors: Vec<u32> = (0..5_000u32)
            .map(|i| i.wrapping_mul(0x0001_0307) & 0x00ff_ffff | 0xff00_0000)
            .collect();
        let mut words = Vec::new();
        measure("lossless encode_vec", &mut || {
            words = lossless
                .encode_vec(&colors, LosslessVariant::Rgb888, None)
                .unwrap();
        });
        let c = measure("lossless decode_vec", &mut || {
            assert_eq!(
                lossless.decode_vec(&words, colors.len(), None).unwrap(),
                colors
            );
        });
        assert_eq!(c, one);
        for (name, cost) in &rows {
            println!("| {name} | {} | {} |", cost.submissions, cost.host_waits);
        }
    }
    assert_clean(&ctx);
}

/// The recorded forms compose: an upload, a find-or-insert, a read pass and the readbacks in a
/// caller's one recording (one submission, one wait), then a recorded GC.
#[test]
fn hash_passes_record_into_a_callers_commands() {
    let ctx = common::gpu();
    {
        let mut table =
            GpuHashTable::new(&ctx, &HashTableConfig::new(HashVariant::AccelHash8, 3, 32)).unwrap();
        let count = 1_500u32;
        let items: Vec<u32> = (1..=count).flat_map(|i| [i, i ^ 0x55, i * 3]).collect();
        let item_buf = ctx
            .create_buffer("items", items.len() as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let handles = ctx
            .create_buffer("handles", count as u64 * 4, MemLocation::GpuOnly)
            .unwrap();
        let out = ctx
            .create_buffer(
                "read back items",
                items.len() as u64 * 4,
                MemLocation::GpuOnly,
            )
            .unwrap();
        table.reserve(count).unwrap();
        let before = ctx.stats();
        let mut cmd = ctx.begin_commands("caller frame").unwrap();
        cmd.upload(&item_buf, 0, &items).unwrap();
        let pending = table
            .record_insert(&mut cmd, &item_buf, &handles, count, true, None)
            .unwrap();
        table
            .record_read_items(&mut cmd, &handles, &out, count, None)
            .unwrap();
        let words: Readback<u32> = cmd.readback(&out, 0, items.len()).unwrap();
        let raw: Readback<u32> = cmd.readback(&handles, 0, count as usize).unwrap();
        cmd.submit_async().unwrap();
        let report = table
            .finish_insert(pending, &item_buf, &handles, count, None)
            .unwrap();
        assert_eq!(report.rounds, 1);
        assert_eq!(words.read().unwrap(), items);
        let raw = raw.read().unwrap();
        assert_eq!(
            ctx.stats().since(before),
            GpuStats {
                submissions: 1,
                host_waits: 1
            }
        );
        // GC recorded by the caller: keep the first half.
        let gc = GpuGarbageCollector::new(&ctx, &table).unwrap();
        let live = ctx.upload("live", &raw[..750]).unwrap();
        let mut cmd = ctx.begin_commands("caller gc").unwrap();
        let pending = gc
            .record_collect(&mut cmd, &table, &live, 750, None)
            .unwrap();
        cmd.submit_async().unwrap();
        let gc_report = gc.finish_collect(pending).unwrap();
        assert_eq!(gc_report.freed_items, count - 750);
        assert_eq!(gc_report.bad_handles, 0);
        let found = table.search(&items, None).unwrap();
        assert!(found[..750].iter().all(Option::is_some));
        assert!(found[750..].iter().all(Option::is_none));
    }
    assert_clean(&ctx);
}
