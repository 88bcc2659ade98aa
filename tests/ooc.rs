//! Out-of-core path tracing: the batched renderer equals the in-core one bit for bit (proxies on
//! and off, several budgets, every eviction and schedule policy), the policies choose as
//! hand-checked, proxies are conservative, corrupt scene files are errors naming
//! file and offset.

mod common;

use std::path::Path;

use indicatif::ProgressBar;
use voxdag::dag::DagError;
use voxdag::ooc::prepare::{Instance, SourceMesh};
use voxdag::ooc::{
    format, prepare, render_in_core, render_out_of_core, Eviction, Grid, OocError, OocScene,
    PrepareOptions, ProxySet, RenderOptions, RenderStats, Resident, SceneSource, Schedule,
};
use voxdag::scene::{self, ImportOptions};

fn avocado() -> SourceMesh {
    let path = common::repo().join("assets/avocado/Avocado.gltf");
    let mesh = scene::load_mesh(&path, &ImportOptions::default()).expect("load avocado");
    SourceMesh::from_mesh(&mesh).unwrap()
}

/// A test's scratch folder, removed when dropped (also when the test fails).
struct Scratch(tempfile::TempDir);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self.0.path()
    }
}

fn scratch(name: &str) -> Scratch {
    let dir = tempfile::Builder::new()
        .prefix(&format!("voxdag-ooc-test-{name}-"))
        .tempdir()
        .unwrap();
    Scratch(dir)
}

fn prepared(source: &SceneSource, name: &str, k: u32, resolutions: &[u32]) -> Scratch {
    let dir = scratch(name);
    let options = PrepareOptions {
        batch_triangles: k,
        proxy_resolutions: resolutions.to_vec(),
        ..Default::default()
    };
    prepare(source, &dir, &options, &ProgressBar::hidden()).expect("prepare");
    dir
}

/// Every combination of the three lists, in order.
fn combos<A: Copy, B: Copy, C: Copy>(a: [A; 3], b: [B; 2], c: [C; 2]) -> Vec<(A, B, C)> {
    let mut out = Vec::new();
    for x in a {
        for y in b {
            for z in c {
                out.push((x, y, z));
            }
        }
    }
    out
}

/// Runs the CLI and asserts success.
fn voxdag_ok(args: &[&str]) -> std::process::Output {
    common::assert_cli_ok(args, common::voxdag_cli(args))
}

fn bits(image: &voxdag::ooc::Image) -> Vec<[u32; 3]> {
    image.pixels.iter().map(|p| p.map(f32::to_bits)).collect()
}

/// Every triangle of every point lies in the union of its proxy voxels: each voxel the closed
/// triangle overlaps is set, and so is the cell of each vertex and of the centroid.
fn check_conservative(dir: &Path, resolution: u32) -> usize {
    let scene = OocScene::open(dir).unwrap();
    let set = ProxySet::read(
        &dir.join(format::proxy_file(resolution)),
        scene.points.len() as u32,
    )
    .unwrap();
    let mut checked = 0;
    for (i, p) in scene.points.iter().enumerate() {
        let grid = Grid::new(&p.bounds, resolution);
        for t in scene.read_point(i as u32).unwrap() {
            let mut any = false;
            grid.for_overlapped(&t, |v| {
                any = true;
                assert!(set.contains(i as u32, v), "point {i}: voxel {v:?} missing");
            });
            assert!(any, "point {i}: a triangle overlaps no voxel");
            // The separating-axis test itself on every cell of the vertices' cell box (the
            // voxelizer skips it for triangles inside one cell).
            let gt = grid.triangle(&t);
            let cells = t.map(|v| grid.cell(grid.to_grid(v)));
            let lo = [0, 1, 2].map(|k| cells.iter().map(|c| c[k]).min().unwrap());
            let hi = [0, 1, 2].map(|k| cells.iter().map(|c| c[k]).max().unwrap());
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        if voxdag::scene::voxelize::tri_box_overlap(&gt, [x, y, z]) {
                            assert!(set.contains(i as u32, [x, y, z]), "point {i}: overlap");
                        }
                    }
                }
            }
            let c = [0, 1, 2].map(|k| (t[0][k] + t[1][k] + t[2][k]) / 3.0);
            for v in [t[0], t[1], t[2], c] {
                let cell = grid.cell(grid.to_grid(v));
                assert!(
                    set.contains(i as u32, cell),
                    "point {i}: vertex cell {cell:?} missing"
                );
            }
            checked += 1;
        }
    }
    checked
}

#[test]
fn out_of_core_equals_in_core_bit_for_bit() {
    let source = SceneSource::landscape(vec![avocado()], 60_000, 7).unwrap();
    let dir = prepared(&source, "equal", 3000, &[32]);
    let scene = OocScene::open(&dir).unwrap();
    assert!(scene.points.len() > 10, "{} points", scene.points.len());
    let proxies = ProxySet::read(&dir.join("proxies-32.bin"), scene.points.len() as u32).unwrap();
    let base = RenderOptions {
        width: 40,
        height: 30,
        spp: 2,
        seed: 3,
        max_bounces: 2,
        rays_in_flight: 512,
        ..Default::default()
    };
    let (reference, ref_stats) = render_in_core(&scene, &base, &ProgressBar::hidden()).unwrap();
    assert!(ref_stats.rays > ref_stats.paths, "paths bounce");
    assert!(
        reference.pixels.iter().any(|p| *p != reference.pixels[0]),
        "a flat image"
    );
    let largest = scene.points.iter().map(|p| p.bytes()).max().unwrap();
    for (budget_points, with_proxies, lookahead) in
        combos([2u64, 6, 1000], [false, true], [false, true])
    {
        {
            let opts = RenderOptions {
                memory_budget: proxies.bytes() + budget_points * 3 * largest,
                lookahead,
                ..base.clone()
            };
            let set = with_proxies.then_some(&proxies);
            let (image, stats) =
                render_out_of_core(&scene, set, &opts, &ProgressBar::hidden()).unwrap();
            assert_eq!(
                bits(&image),
                bits(&reference),
                "budget {budget_points} points, proxies {with_proxies}, lookahead {lookahead}"
            );
            if !lookahead {
                assert_eq!(stats.speculative_visits + stats.requeued_rays, 0);
            }
            assert_eq!(stats.rays, ref_stats.rays);
            assert!(stats.peak_cache_bytes <= opts.memory_budget - stats.proxy_bytes);
            assert_eq!(stats.cache_hits + stats.cache_misses, stats.batching_events);
            if budget_points == 2 {
                assert!(
                    stats.cache_misses > scene.points.len() as u64 / 2,
                    "{stats:?}"
                );
            }
            if with_proxies {
                assert!(stats.proxy_culls > 0, "{stats:?}");
            }
        }
    }
}

#[test]
fn eviction_and_schedule_choose_as_hand_checked() {
    let r = |id, last_used, demand| Resident {
        id,
        last_used,
        demand,
    };
    // Point 4 was used last but no queued ray needs it; 7 is the oldest but 3 rays need it;
    // 2 and 9 are needed by one ray each.
    let resident = [r(7, 1, 3), r(2, 5, 1), r(4, 9, 0), r(9, 3, 1)];
    assert_eq!(Eviction::Lru.victim(resident), Some(7));
    assert_eq!(Eviction::Demand.victim(resident), Some(4));
    // Without 4: the fewest rays (2 and 9: one each), then the least recently used (9).
    assert_eq!(
        Eviction::Demand.victim([resident[0], resident[1], resident[3]]),
        Some(9)
    );
    // Equal keys: the lowest id.
    assert_eq!(Eviction::Demand.victim([r(5, 2, 0), r(3, 2, 0)]), Some(3));
    assert_eq!(Eviction::Lru.victim([]), None);
    // (point, queued, demand): 1 is the fullest, but 6 more of its rays are still coming;
    // net: 1 -> 10 - 6 = 4, 8 -> 7 - 0 = 7, 3 -> 7 - 2 = 5.
    let queues = [(1, 10, 6), (8, 7, 0), (3, 7, 2)];
    assert_eq!(Schedule::Fullest.choose(queues), Some(1));
    assert_eq!(Schedule::Net.choose(queues), Some(8));
    // Ties: the lowest id.
    assert_eq!(Schedule::Net.choose([(6, 4, 1), (2, 3, 0)]), Some(2));
    assert_eq!(Schedule::Fullest.choose([(6, 4, 1), (2, 4, 0)]), Some(2));
    assert_eq!(Schedule::Net.choose([]), None);
}

/// Every eviction and schedule policy renders the in-core image bit for bit; on this scene
/// the default (demand, net) reads fewer bytes than the published LRU and fullest queue.
#[test]
fn policies_render_identical_images() {
    let source = SceneSource::landscape(vec![avocado()], 60_000, 11).unwrap();
    let dir = prepared(&source, "policies", 2000, &[32]);
    let scene = OocScene::open(&dir).unwrap();
    let proxies = ProxySet::read(&dir.join("proxies-32.bin"), scene.points.len() as u32).unwrap();
    let base = RenderOptions {
        width: 40,
        height: 30,
        spp: 2,
        seed: 5,
        max_bounces: 2,
        rays_in_flight: 4096,
        ..Default::default()
    };
    assert_eq!(
        (base.eviction, base.schedule),
        (Eviction::Demand, Schedule::Net)
    );
    let (reference, _) = render_in_core(&scene, &base, &ProgressBar::hidden()).unwrap();
    let largest = scene.points.iter().map(|p| p.bytes()).max().unwrap();
    for with_proxies in [false, true] {
        let set = with_proxies.then_some(&proxies);
        let mut read = Vec::new();
        for (eviction, schedule) in [
            (Eviction::Lru, Schedule::Fullest),
            (Eviction::Demand, Schedule::Fullest),
            (Eviction::Lru, Schedule::Net),
            (Eviction::Demand, Schedule::Net),
        ] {
            let opts = RenderOptions {
                memory_budget: proxies.bytes() + 8 * largest,
                eviction,
                schedule,
                ..base.clone()
            };
            let (image, stats): (_, RenderStats) =
                render_out_of_core(&scene, set, &opts, &ProgressBar::hidden()).unwrap();
            let what = format!("{eviction:?} {schedule:?} proxies {with_proxies}");
            assert_eq!(bits(&image), bits(&reference), "{what}");
            assert_eq!(stats.eviction, Some(eviction));
            assert!(
                stats.cache_misses > stats.points_loaded,
                "{what}: reloads {stats:?}"
            );
            read.push(stats.disk_bytes_read);
        }
        assert!(
            read[3] < read[0],
            "proxies {with_proxies}: bytes read {read:?}"
        );
    }
}

#[test]
fn proxies_are_conservative_on_assets() {
    let source = SceneSource::landscape(vec![avocado()], 20_000, 1).unwrap();
    let dir = prepared(&source, "conservative", 1500, &[8, 128]);
    assert!(check_conservative(&dir, 128) > 0);
    assert!(check_conservative(&dir, 8) > 0);
    // A single untransformed avocado: one point.
    let one = SceneSource {
        meshes: vec![avocado()],
        instances: vec![Instance {
            mesh: 0,
            transform: [
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
            ],
        }],
        terrain: None,
    };
    let dir = prepared(&one, "conservative-one", 100_000, &[128]);
    assert_eq!(OocScene::open(&dir).unwrap().points.len(), 1);
    assert!(check_conservative(&dir, 128) > 0);
}

#[test]
fn proxies_are_conservative_on_shared_meshes() {
    let Some(data) = common::shared_data() else {
        return;
    };
    for name in ["bunny", "dragon", "buddha", "horse", "teapot"] {
        let path = data.join(format!("meshes/{name}.obj"));
        let mesh = scene::load_mesh(&path, &ImportOptions::default()).unwrap();
        let source = SceneSource {
            meshes: vec![SourceMesh::from_mesh(&mesh).unwrap()],
            instances: vec![Instance {
                mesh: 0,
                transform: [
                    [1.0, 0.0, 0.0, 0.0],
                    [0.0, 1.0, 0.0, 0.0],
                    [0.0, 0.0, 1.0, 0.0],
                ],
            }],
            terrain: None,
        };
        let dir = prepared(&source, name, 20_000, &[64]);
        let n = check_conservative(&dir, 64);
        assert_eq!(n, mesh.triangles.len(), "{name}");
    }
}

#[test]
fn proxy_nodes_are_shared_across_points() {
    let source = SceneSource::landscape(vec![avocado()], 20_000, 2).unwrap();
    let dir = prepared(&source, "shared", 1000, &[64]);
    let scene = OocScene::open(&dir).unwrap();
    let set = ProxySet::read(&dir.join("proxies-64.bin"), scene.points.len() as u32).unwrap();
    let mut separate = 0;
    for (i, p) in scene.points.iter().enumerate() {
        let grid = Grid::new(&p.bounds, 64);
        let tris = scene.read_point(i as u32).unwrap();
        let dag =
            voxdag::dag::Svdag::from_voxels(&voxdag::ooc::proxy::voxelize_point(&tris, &grid))
                .unwrap();
        separate += dag.words.len();
    }
    assert!(
        set.words.len() < separate,
        "{} vs {separate}",
        set.words.len()
    );
}

fn expect_format_error(result: Result<impl std::fmt::Debug, OocError>, file: &str) -> u64 {
    match result {
        Err(OocError::Dag(DagError::Format { path, offset, .. })) => {
            assert!(path.ends_with(file), "{path:?}");
            offset
        }
        other => panic!("expected a format error in {file}, got {other:?}"),
    }
}

#[test]
fn corrupt_scene_files_are_errors_with_file_and_offset() {
    let source = SceneSource::landscape(vec![avocado()], 10_000, 3).unwrap();
    let dir = prepared(&source, "corrupt", 2000, &[16]);
    let scene = OocScene::open(&dir).unwrap();
    let n = scene.points.len() as u32;
    let p1 = scene.points[1];
    drop(scene);
    let geometry = dir.join("geometry.bin");
    let original = std::fs::read(&geometry).unwrap();
    // A flipped byte inside point 1's region: its checksum fails, naming the region's offset.
    let mut bad = original.clone();
    bad[p1.offset as usize + 5] ^= 0x40;
    std::fs::write(&geometry, &bad).unwrap();
    let scene = OocScene::open(&dir).unwrap();
    assert!(scene.read_point(0).is_ok());
    assert_eq!(
        expect_format_error(scene.read_point(1), "geometry.bin"),
        p1.offset
    );
    // The renderers stop with that error rather than drawing a wrong image.
    let opts = RenderOptions {
        width: 16,
        height: 16,
        spp: 1,
        ..Default::default()
    };
    assert!(render_in_core(&scene, &opts, &ProgressBar::hidden()).is_err());
    drop(scene);
    // Truncated geometry: the index names the expected size.
    std::fs::write(&geometry, &original[..original.len() - 7]).unwrap();
    let offset = expect_format_error(OocScene::open(&dir), "geometry.bin");
    assert_eq!(offset, original.len() as u64 - 7);
    std::fs::write(&geometry, &original).unwrap();
    // Truncated and corrupt index.
    let index = dir.join("index.bin");
    let idx = std::fs::read(&index).unwrap();
    std::fs::write(&index, &idx[..idx.len() - 10]).unwrap();
    expect_format_error(OocScene::open(&dir), "index.bin");
    let mut bad = idx.clone();
    bad[70] ^= 1;
    std::fs::write(&index, &bad).unwrap();
    expect_format_error(OocScene::open(&dir), "index.bin");
    std::fs::write(&index, &idx).unwrap();
    // Corrupt and truncated proxies.
    let proxies = dir.join("proxies-16.bin");
    let px = std::fs::read(&proxies).unwrap();
    let mut bad = px.clone();
    bad[40] ^= 2;
    std::fs::write(&proxies, &bad).unwrap();
    expect_format_error(ProxySet::read(&proxies, n), "proxies-16.bin");
    std::fs::write(&proxies, &px[..px.len() / 2]).unwrap();
    expect_format_error(ProxySet::read(&proxies, n), "proxies-16.bin");
    // The CLI prints one line naming the file and the offset.
    std::fs::write(&proxies, &px).unwrap();
    std::fs::write(&geometry, &original[..original.len() - 7]).unwrap();
    let out_png = dir.join("x.png");
    let out = common::voxdag_cli(&[
        "ooc",
        "render",
        dir.to_str().unwrap(),
        "--size",
        "8x8",
        "--spp",
        "1",
        "--out",
        out_png.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("geometry.bin")
            && err.contains(&format!("byte offset {}", original.len() - 7)),
        "{err}"
    );
    assert!(!out_png.exists());
}

#[test]
fn cli_generate_prepare_render() {
    let dir = scratch("cli");
    let avocado = common::repo().join("assets/avocado/Avocado.gltf");
    let scene_dir = dir.join("scene");
    voxdag_ok(&[
        "-q",
        "ooc",
        "generate",
        "--triangles",
        "8k",
        "--seed",
        "5",
        "--meshes",
        avocado.to_str().unwrap(),
        "--batch-triangles",
        "1000",
        "--proxy-resolution",
        "16,32",
        "-o",
        scene_dir.to_str().unwrap(),
    ]);
    let forest_dir = dir.join("forest");
    voxdag_ok(&[
        "-q",
        "ooc",
        "generate",
        "--kind",
        "forest",
        "--triangles",
        "30k",
        "--meshes",
        avocado.to_str().unwrap(),
        "--batch-triangles",
        "4000",
        "-o",
        forest_dir.to_str().unwrap(),
    ]);
    let forest = OocScene::open(&forest_dir).unwrap();
    assert!(forest.triangles >= 30_000, "{}", forest.triangles);
    let inst = dir.join("instances.txt");
    std::fs::write(&inst, "# two copies\n0 10 0 0 0\n0 10 5 0 0 90\n").unwrap();
    let prepared_dir = dir.join("prepared");
    voxdag_ok(&[
        "-q",
        "ooc",
        "prepare",
        avocado.to_str().unwrap(),
        "--instances",
        inst.to_str().unwrap(),
        "--batch-triangles",
        "300",
        "-o",
        prepared_dir.to_str().unwrap(),
    ]);
    let mut images = Vec::new();
    for (name, ext, extra) in [
        ("in", "png", vec!["--in-core"]),
        (
            "on",
            "png",
            vec![
                "--proxies",
                "on",
                "--proxy-resolution",
                "32",
                "--memory-budget",
                "300K",
            ],
        ),
        (
            "off",
            "png",
            vec!["--proxies", "off", "--memory-budget", "300K"],
        ),
        ("in", "exr", vec!["--in-core"]),
        (
            "off",
            "exr",
            vec!["--proxies", "off", "--memory-budget", "300K"],
        ),
        (
            "lru",
            "png",
            vec![
                "--memory-budget",
                "300K",
                "--proxy-resolution",
                "32",
                "--eviction",
                "lru",
                "--schedule",
                "fullest",
            ],
        ),
    ] {
        let image = dir.join(format!("{name}.{ext}"));
        let report = dir.join(format!("{name}.json"));
        let mut args = vec![
            "-q",
            "ooc",
            "render",
            scene_dir.to_str().unwrap(),
            "--size",
            "24x16",
            "--spp",
            "2",
            "--out",
            image.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ];
        args.extend(extra);
        voxdag_ok(&args);
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
        for key in [
            "disk_bytes_read",
            "batching_events",
            "cache_hits",
            "cache_misses",
            "rays_per_s",
            "wall_s",
        ] {
            assert!(json.get(key).is_some(), "{key} missing");
        }
        if name != "in" {
            let policies = (&json["eviction"], &json["schedule"]);
            if name == "lru" {
                assert_eq!(policies, (&"lru".into(), &"fullest".into()));
            } else {
                assert_eq!(policies, (&"demand".into(), &"net".into()), "defaults");
            }
        }
        images.push(std::fs::read(&image).unwrap());
    }
    assert_eq!(images[0], images[1]);
    assert_eq!(images[0], images[2]);
    assert_eq!(
        images[0], images[5],
        "LRU and the fullest queue: the same image"
    );
    assert_eq!(images[3], images[4], "EXR: out of core equals in core");
    // The EXR holds the linear radiance the PNG was tonemapped from.
    let exr = image::load_from_memory(&images[3]).unwrap().to_rgb32f();
    let png = image::load_from_memory(&images[0]).unwrap().to_rgba8();
    assert_eq!((exr.width(), exr.height()), (24, 16));
    for (e, p) in exr.pixels().zip(png.pixels()) {
        for k in 0..3 {
            let srgb = voxdag::color::linear_to_srgb(e.0[k].clamp(0.0, 1.0));
            assert_eq!((srgb * 255.0 + 0.5) as u8, p.0[k]);
        }
    }
    let bad = dir.join("x.bmp");
    let out = common::voxdag_cli(&[
        "-q",
        "ooc",
        "render",
        scene_dir.to_str().unwrap(),
        "--in-core",
        "--out",
        bad.to_str().unwrap(),
    ]);
    assert!(!out.status.success(), "a .bmp output is refused");
    assert!(!bad.exists());
}

/// Names in `dir`, sorted.
fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn failed_prepare_leaves_no_temporary_files() {
    let source = SceneSource::landscape(vec![avocado()], 20_000, 5).unwrap();
    // Tiny buckets: the grouping regenerates the triangles bucket by bucket, as for a scene
    // larger than memory.
    let options = PrepareOptions {
        batch_triangles: 2000,
        proxy_resolutions: vec![16],
        bucket_bytes: 1 << 14,
    };
    // A non-empty directory where `geometry.bin` goes: every byte is written, the final rename
    // fails.
    let failed_geometry = scratch("fail-geometry");
    let dir = &failed_geometry;
    std::fs::create_dir_all(dir.join(format::GEOMETRY_FILE).join("x")).unwrap();
    let err = prepare(&source, dir, &options, &ProgressBar::hidden()).unwrap_err();
    assert!(
        err.to_string().contains(format::GEOMETRY_FILE),
        "the error names the file: {err}"
    );
    assert_eq!(listing(dir), [format::GEOMETRY_FILE]);
    // The same where the proxies go: geometry is written, the proxy file fails.
    let failed_proxies = scratch("fail-proxies");
    let dir = &failed_proxies;
    let proxies = format::proxy_file(16);
    std::fs::create_dir_all(dir.join(&proxies).join("x")).unwrap();
    let err = prepare(&source, dir, &options, &ProgressBar::hidden()).unwrap_err();
    assert!(err.to_string().contains(&proxies), "{err}");
    assert_eq!(listing(dir), [format::GEOMETRY_FILE.to_string(), proxies]);
    // And the same options succeed in a clean directory with only the scene files.
    let clean = scratch("no-failure");
    prepare(&source, &clean, &options, &ProgressBar::hidden()).unwrap();
    assert_eq!(
        listing(&clean),
        [format::GEOMETRY_FILE, format::INDEX_FILE, "proxies-16.bin"]
    );
}

/// All triangles of a scene directory as bit patterns, sorted.
fn triangle_multiset(dir: &Path) -> Vec<[[u32; 3]; 3]> {
    let scene = OocScene::open(dir).unwrap();
    let mut all = Vec::new();
    for i in 0..scene.points.len() as u32 {
        all.extend(
            scene
                .read_point(i)
                .unwrap()
                .iter()
                .map(|t| t.map(|v| v.map(f32::to_bits))),
        );
    }
    all.sort_unstable();
    all
}

#[test]
fn bucketed_grouping_keeps_every_triangle_once() {
    // Terrain plus copies; tiny buckets cut the scene into many boxes that copies and terrain
    // cells straddle: each bucket regenerates only what reaches its box.
    let source = SceneSource::landscape(vec![avocado()], 60_000, 11).unwrap();
    let whole = prepared(&source, "bucket-whole", 2000, &[16]);
    let cut = scratch("bucket-cut");
    let options = PrepareOptions {
        batch_triangles: 2000,
        proxy_resolutions: vec![16],
        bucket_bytes: 1 << 13,
    };
    prepare(&source, &cut, &options, &ProgressBar::hidden()).unwrap();
    let (a, b) = (triangle_multiset(&whole), triangle_multiset(&cut));
    assert_eq!(a.len() as u64, source.triangle_count());
    assert!(a == b, "the bucketed scene holds other triangles");
    let points = |d: &Path| OocScene::open(d).unwrap().points.len();
    assert!(points(&cut) > points(&whole), "the buckets cut points");
}

/// The forest scene (procedural trees: thin branches, leaf clusters): its proxies are
/// conservative on every leaf, the out-of-core image equals the in-core one with proxies on
/// and off, and the proxies cull rays that cross the trees' points between the leaves.
#[test]
fn forest_renders_as_in_core_and_its_proxies_are_conservative() {
    let source = SceneSource::forest(vec![avocado()], 200_000, 4).unwrap();
    let trees = source.meshes.len() - 1;
    assert!(trees >= 4, "{trees} tree variants");
    let dir = prepared(&source, "forest", 4000, &[64]);
    let scene = OocScene::open(&dir).unwrap();
    assert!(scene.triangles >= 200_000, "{}", scene.triangles);
    assert_eq!(check_conservative(&dir, 64) as u64, scene.triangles);
    let proxies = ProxySet::read(&dir.join("proxies-64.bin"), scene.points.len() as u32).unwrap();
    // Look across a grove (the first tree's) from close by, so that rays cross its points.
    let tree = source
        .instances
        .iter()
        .find(|i| i.mesh > 0)
        .expect("a tree")
        .transform;
    let at = [
        tree[0][3] as f32,
        tree[1][3] as f32 + 10.0,
        tree[2][3] as f32,
    ];
    let base = RenderOptions {
        width: 40,
        height: 30,
        spp: 2,
        seed: 9,
        max_bounces: 2,
        rays_in_flight: 1024,
        eye: Some([at[0] - 60.0, at[1] + 15.0, at[2] - 60.0]),
        target: Some(at),
        ..Default::default()
    };
    let (reference, _) = render_in_core(&scene, &base, &ProgressBar::hidden()).unwrap();
    let largest = scene.points.iter().map(|p| p.bytes()).max().unwrap();
    let opts = RenderOptions {
        memory_budget: proxies.bytes() + 4 * largest,
        ..base.clone()
    };
    let mut read = Vec::new();
    for set in [None, Some(&proxies)] {
        let (image, stats) =
            render_out_of_core(&scene, set, &opts, &ProgressBar::hidden()).unwrap();
        assert_eq!(bits(&image), bits(&reference), "proxies {}", set.is_some());
        if set.is_some() {
            assert!(stats.proxy_culls > 0, "{stats:?}");
        }
        read.push(stats.disk_bytes_read);
    }
    assert!(read[1] < read[0], "bytes read off / on: {read:?}");
}

/// `bench ooc` on a tiny forest: Figures 6.3 and 6.2 and the policy table (four policies, the
/// same in both modes, one image), whose best-against-best ratio pairs each mode's fewest bytes.
#[test]
fn bench_ooc_reports_figures_and_policies() {
    let dir = scratch("bench");
    let avocado = common::repo().join("assets/avocado/Avocado.gltf");
    let (json, md) = (dir.join("b.json"), dir.join("b.md"));
    let scene_dir = dir.join("scene");
    voxdag_ok(&[
        "-q",
        "bench",
        "ooc",
        "--kind",
        "forest",
        "--triangles",
        "40000",
        "--meshes",
        avocado.to_str().unwrap(),
        "--batch-triangles",
        "2000",
        "--scene",
        scene_dir.to_str().unwrap(),
        "--budgets",
        "0.25",
        "--proxy-resolution",
        "16",
        "--resolutions",
        "16,32",
        "--policy-budget",
        "0.3",
        "--size",
        "16x12",
        "--spp",
        "1",
        "--json",
        json.to_str().unwrap(),
        "--markdown",
        md.to_str().unwrap(),
    ]);
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(report["budgets"].as_array().unwrap().len(), 1);
    assert_eq!(report["resolutions"].as_array().unwrap().len(), 2);
    let policies = report["policies"].as_array().unwrap();
    let names: Vec<String> = policies
        .iter()
        .map(|p| format!("{} {}", p["eviction"], p["schedule"]))
        .collect();
    assert_eq!(
        names,
        [
            "\"demand\" \"net\"",
            "\"demand\" \"fullest\"",
            "\"lru\" \"net\"",
            "\"lru\" \"fullest\""
        ]
    );
    let bytes = |mode: &str| {
        policies
            .iter()
            .map(|p| p[mode]["disk_bytes_read"].as_u64().unwrap())
            .min()
            .unwrap()
    };
    let best = bytes("off") as f64 / bytes("on") as f64;
    let reported = report["best_against_best"].as_f64().unwrap();
    assert!((reported - best).abs() < 1e-9, "{reported} vs {best}");
    let text = std::fs::read_to_string(&md).unwrap();
    assert!(text.contains("Each mode at its best policy"), "{text}");
    // The table names the policies as the JSON and the CLI do.
    for row in [
        "| demand, net |",
        "| demand, fullest |",
        "| lru, net |",
        "| lru, fullest |",
    ] {
        assert!(text.contains(row), "{row}: {text}");
    }
}
