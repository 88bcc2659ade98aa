//! Helpers shared by the integration tests: data locations, scene building, the GPU context and
//! image comparison with actual/difference PNGs on failure.
#![allow(dead_code)] // each test binary uses a different subset

pub mod xvfb;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use voxdag::dag::Svdag;
use voxdag::gpu::test_layouts::DecodeTestPush;
use voxdag::gpu::{ComputePipelineDesc, GpuContext, GpuOptions, MemLocation};
use voxdag::render::RenderOutput;
use voxdag::scene::{self, ImportOptions};

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `../shared/data`, or `None` after printing the one `skipped:` line the test policy asks for.
pub fn shared_data() -> Option<PathBuf> {
    let dir = repo().join("../shared/data");
    if dir.is_dir() {
        Some(dir)
    } else {
        // Straight to the stderr handle: the test harness captures print!/eprint! output, and this
        // line must be visible in CI logs.
        let test = std::thread::current().name().unwrap_or("test").to_string();
        let _ = writeln!(
            std::io::stderr(),
            "skipped: {test}: ../shared/data not found"
        );
        None
    }
}

/// Imports and builds a scene at a resolution (no progress bar).
pub fn build_scene(path: &Path, resolution: Option<u32>) -> Svdag {
    let options = ImportOptions {
        resolution,
        ..Default::default()
    };
    let voxels = scene::import(path, &options, &indicatif::ProgressBar::hidden())
        .unwrap_or_else(|e| panic!("importing {}: {e}", path.display()));
    Svdag::from_voxels(&voxels).expect("build SVDAG")
}

/// Runs the `voxdag` binary of this build with `args` and returns what it printed and its status.
pub fn voxdag_cli(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_voxdag"))
        .args(args)
        .output()
        .expect("run voxdag")
}

/// Asserts that the `voxdag` run of `args` that printed `out` succeeded (its stderr in the message
/// otherwise); returns `out`.
pub fn assert_cli_ok(args: &[&str], out: std::process::Output) -> std::process::Output {
    assert!(
        out.status.success(),
        "voxdag {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A GPU context with validation on; fails (never skips) when no Vulkan device exists.
pub fn gpu() -> Arc<GpuContext> {
    ensure_runtime_dir();
    let options = GpuOptions {
        validation: true,
        ..GpuOptions::default()
    };
    GpuContext::new(&options)
        .expect("a Vulkan device is required for this test (lavapipe is enough)")
}

/// Mesa warns without XDG_RUNTIME_DIR; give it a private one when the environment has none.
fn ensure_runtime_dir() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
        let dir = std::env::temp_dir().join(format!("voxdag-xdg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // Set before the first Vulkan call of this process; concurrent callers write the same value.
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    }
}

/// Where failing image tests write their actual and difference PNGs.
pub fn failure_dir() -> PathBuf {
    let dir = repo().join("target/test-failures");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Outcome of comparing two RGBA8 images.
pub struct ImageDiff {
    /// Pixels whose largest channel difference exceeds the per-channel tolerance.
    pub differing: usize,
    /// Largest channel difference anywhere.
    pub max_delta: u8,
    /// A visualisation: differing pixels red, the rest a dimmed copy of the expected image.
    pub diff_rgba: Vec<u8>,
}

/// Compares two images of equal size channel by channel.
pub fn compare(expected: &[u8], actual: &[u8], channel_tolerance: u8) -> ImageDiff {
    assert_eq!(expected.len(), actual.len(), "image sizes differ");
    let mut differing = 0;
    let mut max_delta = 0;
    let mut diff_rgba = Vec::with_capacity(expected.len());
    for (e, a) in expected.chunks_exact(4).zip(actual.chunks_exact(4)) {
        let delta = e.iter().zip(a).map(|(x, y)| x.abs_diff(*y)).max().unwrap();
        max_delta = max_delta.max(delta);
        if delta > channel_tolerance {
            differing += 1;
            diff_rgba.extend_from_slice(&[255, 0, 0, 255]);
        } else {
            diff_rgba.extend_from_slice(&[e[0] / 3, e[1] / 3, e[2] / 3, 255]);
        }
    }
    ImageDiff {
        differing,
        max_delta,
        diff_rgba,
    }
}

/// Saves an RGBA8 image as PNG.
pub fn save_png(path: &Path, width: u32, height: u32, rgba: &[u8]) {
    image::save_buffer(path, rgba, width, height, image::ExtendedColorType::Rgba8).unwrap();
}

/// Compares a render with `tests/golden/NAME.png`: at most `max_fraction` of the pixels may differ by
/// more than `channel_tolerance` in some channel. On failure writes NAME.actual.png and NAME.diff.png
/// under target/test-failures. With `VOXDAG_BLESS=1` (re)writes the golden instead.
pub fn check_golden(name: &str, image: &RenderOutput, channel_tolerance: u8, max_fraction: f64) {
    let golden = repo().join("tests/golden").join(format!("{name}.png"));
    if std::env::var("VOXDAG_BLESS").as_deref() == Ok("1") {
        assert!(
            std::env::var_os("CI").is_none(),
            "VOXDAG_BLESS must not be set in CI: goldens would not be checked"
        );
        save_png(&golden, image.width, image.height, &image.rgba);
        println!("blessed {}", golden.display());
        return;
    }
    let expected = image::open(&golden)
        .unwrap_or_else(|e| {
            panic!(
                "golden {} unreadable ({e}); run with VOXDAG_BLESS=1 to create it",
                golden.display()
            )
        })
        .to_rgba8();
    assert_eq!(
        (expected.width(), expected.height()),
        (image.width, image.height),
        "golden {name} size"
    );
    let diff = compare(expected.as_raw(), &image.rgba, channel_tolerance);
    let allowed = (max_fraction * (image.width * image.height) as f64) as usize;
    if diff.differing > allowed {
        let dir = failure_dir();
        let actual = dir.join(format!("{name}.actual.png"));
        let diff_path = dir.join(format!("{name}.diff.png"));
        save_png(&actual, image.width, image.height, &image.rgba);
        save_png(&diff_path, image.width, image.height, &diff.diff_rgba);
        panic!(
            "golden {name}: {} pixels differ by more than {channel_tolerance} (allowed {allowed}, max delta {}); \
             wrote {} and {}",
            diff.differing,
            diff.max_delta,
            actual.display(),
            diff_path.display()
        );
    }
}

/// Size of the hash timing tests, as log2 of the table items: `VOXDAG_HASH_TIMING_LOG2` (default 14
/// to stay fast in CI; the measurements in docs/hash-gc-dedup.md use 21).
pub fn hash_timing_log2() -> u32 {
    std::env::var("VOXDAG_HASH_TIMING_LOG2")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(14)
}

/// GPU vs CPU render tolerance: the scene fills at least 5% of the image, hit masks differ on at
/// most 0.1% of the pixels (rays grazing exact edges), colours by more than 4 units on at most 0.4%
/// (float evaluation order).
pub fn assert_renders_match(name: &str, gpu_image: &RenderOutput, cpu_image: &RenderOutput) {
    let pixels = gpu_image.hits.len();
    let hits = cpu_image.hit_count();
    assert!(
        hits > pixels / 20,
        "{name}: the camera should see the scene ({hits} hits)"
    );
    let mismatched = gpu_image
        .hits
        .iter()
        .zip(&cpu_image.hits)
        .filter(|(g, c)| g != c)
        .count();
    let allowed = pixels / 1000;
    assert!(
        mismatched <= allowed,
        "{name}: {mismatched} hit-mask pixels differ (allowed {allowed})"
    );
    let diff = compare(&cpu_image.rgba, &gpu_image.rgba, 4);
    assert!(
        diff.differing <= allowed * 4,
        "{name}: {} pixels differ in colour by more than 4",
        diff.differing
    );
}

/// splitmix64: a small seeded generator for reproducible test workloads.
pub struct Rng(pub u64);

impl Rng {
    /// The next 64 random bits.
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A number in `0..n`.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// Whether a TSVDAG has a translated pointer (a nonzero count at a pointer position).
pub fn has_translated_pointer(e: &voxdag::dag::encode::TsvdagEncoding) -> bool {
    let counts = e.stream_voxel_counts().unwrap();
    (1..e.levels.len()).any(|l| {
        let mut starts = std::collections::HashSet::new();
        // Node headers are the positions a sum is stored at; the first node starts at 0 and
        // every node has at least one pointer word, so positions holding a count that are
        // not node starts are translated pointers.
        let stream = &e.levels[l];
        let mut off = 0;
        while off < stream.len() {
            starts.insert(off);
            let h = stream[off];
            off += 1 + (0..8).map(|o| ((h >> (2 * o)) & 3) as usize).sum::<usize>();
        }
        counts[l]
            .iter()
            .enumerate()
            .any(|(i, &c)| c != 0 && !starts.contains(&i))
    })
}

/// Runs a test shader with `DecodeTestPush` push constants (`shaders/glsl/test/*_decode.comp`,
/// `test/xform.comp`): `count` invocations in workgroups of 64 read `input` and write
/// `count * words_per_case` output words, which are returned.
pub fn run_test_shader(
    ctx: &Arc<GpuContext>,
    spirv: &[u32],
    input: &[u32],
    count: usize,
    words_per_case: usize,
) -> Vec<u32> {
    let pipeline = ctx
        .create_compute_pipeline(&ComputePipelineDesc {
            name: "test shader",
            spirv,
            spec_constants: &[],
            push_constant_size: std::mem::size_of::<DecodeTestPush>() as u32,
            bindings: &[],
        })
        .unwrap();
    let input = ctx.upload("test shader input", input).unwrap();
    let out_words = count * words_per_case;
    let out = ctx
        .create_buffer(
            "test shader output",
            out_words.max(1) as u64 * 4,
            MemLocation::GpuOnly,
        )
        .unwrap();
    let push = bytemuck::bytes_of(&DecodeTestPush {
        chunk_addr: input.address(),
        out_addr: out.address(),
        count: count as u32,
        pad: 0,
    })
    .to_vec();
    let mut cmd = ctx.begin_commands("test shader").unwrap();
    cmd.dispatch(
        &pipeline,
        [(count as u32).div_ceil(64).max(1), 1, 1],
        &push,
        &[],
    )
    .unwrap();
    cmd.submit().unwrap();
    let mut got = ctx.download::<u32>(&out).unwrap();
    got.truncate(out_words);
    got
}
