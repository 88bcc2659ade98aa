//! The GPU hash DAG (engine/edit/gpu.rs) on a real device (lavapipe in CI): loading svdag32
//! scenes into the nine per-size tables and reading them back, the sphere / cube edit pipeline
//! against a brute-force edit of a plain voxel grid, deduplication completeness against a CPU
//! canonical build, and pool exhaustion during an edit. Every variant of the tables; every test
//! ends with zero validation messages and zero live allocations.

mod common;

use std::sync::Arc;

use rustc_hash::FxHashMap;
use voxdag::dag::Svdag;
use voxdag::edit::gpu::{GpuDagError, GpuHashDag, GpuHashDagConfig};
use voxdag::edit::item::Root;
use voxdag::edit::tool::{self, Shape, Tool};
use voxdag::gpu::{GpuContext, Profiler};
use voxdag::hash::{HashError, HashVariant};
use voxdag::scene::{morton, Voxels};

fn assert_clean(ctx: &Arc<GpuContext>) {
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

/// Unique canonical nodes per level (index = level) of a voxel set, built bottom-up on the CPU
/// the way the hash DAG stores them (a full leaf or a node of full children is not a node).
fn canonical_level_counts(resolution: u32, codes: &[u64]) -> Vec<u64> {
    const FULL: u64 = u64::MAX - 1;
    const EMPTY: u64 = u64::MAX;
    let root_level = resolution.trailing_zeros() - 2;
    let mut values: FxHashMap<u64, u64> = FxHashMap::default();
    let mut masks: FxHashMap<u64, u64> = FxHashMap::default();
    for &c in codes {
        *masks.entry(c >> 6).or_default() |= 1 << (c & 63);
    }
    let mut ids: FxHashMap<Vec<u64>, u64> = FxHashMap::default();
    for (&at, &mask) in &masks {
        let value = if mask == u64::MAX {
            FULL
        } else {
            let next = ids.len() as u64;
            *ids.entry(vec![mask]).or_insert(next)
        };
        values.insert(at, value);
    }
    let mut counts = vec![ids.len() as u64];
    for _ in 1..=root_level {
        let mut parents: FxHashMap<u64, [u64; 8]> = FxHashMap::default();
        for (&at, &value) in &values {
            parents.entry(at >> 3).or_insert([EMPTY; 8])[(at & 7) as usize] = value;
        }
        ids.clear();
        values.clear();
        for (at, children) in parents {
            let value = if children.iter().all(|&c| c == FULL) {
                FULL
            } else {
                let next = ids.len() as u64;
                *ids.entry(children.to_vec()).or_insert(next)
            };
            values.insert(at, value);
        }
        counts.push(ids.len() as u64);
    }
    counts
}

/// A dense voxel grid indexed by Morton code: the brute-force reference.
struct Grid {
    resolution: u32,
    solid: Vec<bool>,
}

impl Grid {
    fn from_codes(resolution: u32, codes: &[u64]) -> Grid {
        let mut solid = vec![false; (resolution as usize).pow(3)];
        for &c in codes {
            solid[c as usize] = true;
        }
        Grid { resolution, solid }
    }

    fn codes(&self) -> Vec<u64> {
        (0..self.solid.len() as u64)
            .filter(|&c| self.solid[c as usize])
            .collect()
    }

    /// Applies an add / remove tool to every voxel of its bounding box.
    fn apply(&mut self, t: &Tool) {
        let (shape, center, radius, remove) = shape_of(t);
        let n = self.resolution as i64;
        let lo = |c: f32| ((c - radius).floor() as i64 - 1).clamp(0, n) as u32;
        let hi = |c: f32| ((c + radius).ceil() as i64 + 1).clamp(0, n) as u32;
        for z in lo(center[2])..hi(center[2]) {
            for y in lo(center[1])..hi(center[1]) {
                for x in lo(center[0])..hi(center[0]) {
                    let inside = match shape {
                        Shape::Sphere => tool::in_sphere(center, radius, [x, y, z]),
                        Shape::Cube => tool::in_cube(center, radius, [x, y, z]),
                    };
                    if inside {
                        self.solid[morton::encode(x, y, z) as usize] = !remove;
                    }
                }
            }
        }
    }
}

/// Shape, centre, radius and remove flag of an add / remove tool.
fn shape_of(t: &Tool) -> (Shape, [f32; 3], f32, bool) {
    match *t {
        Tool::Add {
            shape,
            center,
            radius,
            ..
        } => (shape, center, radius, false),
        Tool::Remove {
            shape,
            center,
            radius,
        } => (shape, center, radius, true),
        _ => panic!("not an add / remove tool: {t:?}"),
    }
}

/// An add (material 0) or remove tool.
fn shaped(shape: Shape, center: [f32; 3], radius: f32, remove: bool) -> Tool {
    if remove {
        Tool::Remove {
            shape,
            center,
            radius,
        }
    } else {
        Tool::Add {
            shape,
            center,
            radius,
            material: 0,
        }
    }
}

/// Voxels read back from the current root, and its unique nodes per level.
fn read_back(dag: &GpuHashDag) -> (Vec<u64>, Vec<u64>) {
    let image = dag.download().unwrap();
    let voxels = image.voxels(dag.root()).unwrap();
    assert!(voxels.iter().all(|&(_, m)| m == 0), "geometry-only scene");
    let codes: Vec<u64> = voxels.into_iter().map(|(c, _)| c).collect();
    assert!(codes.windows(2).all(|w| w[0] < w[1]), "voxels ascending");
    (codes, image.level_counts(dag.root()).unwrap())
}

/// Deterministic scenes: random noise, solid boxes (full leaves and full nodes) and a ball.
fn synthetic(resolution: u32, seed: u64) -> Voxels {
    let mut rng = common::Rng(seed);
    let n = resolution;
    let mut coords = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let noise = x < n / 4 && rng.below(3) == 0;
                let slab = (n / 2..n / 2 + n / 4).contains(&x) && y < n / 2 + 3;
                let dx = x as f64 - 0.7 * n as f64;
                let dy = y as f64 - 0.6 * n as f64;
                let dz = z as f64 - 0.5 * n as f64;
                let ball = dx * dx + dy * dy + dz * dz < (0.2 * n as f64).powi(2);
                if noise || slab || ball {
                    coords.push([x, y, z]);
                }
            }
        }
    }
    Voxels::from_coords(resolution, coords)
}

fn check_load(ctx: &Arc<GpuContext>, variant: HashVariant, name: &str, dag: &Svdag) {
    let config = GpuHashDagConfig::new(variant, 1024);
    let hd = GpuHashDag::load(ctx, &config, dag, None).unwrap();
    let expected = dag.to_voxels().codes;
    let (codes, counts) = read_back(&hd);
    assert_eq!(
        codes.len(),
        expected.len(),
        "{name} {variant:?}: voxel count"
    );
    assert_eq!(codes, expected, "{name} {variant:?}: voxels");
    assert_eq!(
        counts,
        canonical_level_counts(dag.resolution, &expected),
        "{name} {variant:?}: unique nodes per level"
    );
    let image = hd.download().unwrap();
    let back = image.to_svdag(hd.root()).unwrap();
    let mut geometry = dag.to_voxels();
    geometry.colors.clear();
    assert_eq!(
        back,
        Svdag::from_voxels(&geometry).unwrap(),
        "{name} {variant:?}: to_svdag"
    );
    match (expected.is_empty(), hd.root()) {
        (true, Root::Empty) => {}
        (false, Root::Node(_)) => {}
        (_, Root::Full(0)) if expected.len() == (dag.resolution as usize).pow(3) => {}
        (_, root) => panic!("{name} {variant:?}: root {root:?}"),
    }
}

#[test]
fn load_reads_back_every_scene_for_every_variant() {
    let ctx = common::gpu();
    let mut scenes: Vec<(String, Svdag)> = vec![
        (
            "synthetic 32".into(),
            Svdag::from_voxels(&synthetic(32, 1)).unwrap(),
        ),
        (
            "empty 16".into(),
            Svdag::from_voxels(&Voxels::from_coords(16, [])).unwrap(),
        ),
        (
            "full 8".into(),
            Svdag::from_voxels(&Voxels::from_coords(8, (0..512).map(morton::decode))).unwrap(),
        ),
        (
            "teapot 64".into(),
            common::build_scene(&common::repo().join("tests/data/teapot.obj"), Some(64)),
        ),
        (
            "ff3.vox".into(),
            common::build_scene(&common::repo().join("tests/data/ff3.vox"), None),
        ),
    ];
    scenes.push((
        "avocado 64".into(),
        common::build_scene(
            &common::repo().join("assets/avocado/Avocado.gltf"),
            Some(64),
        ),
    ));
    for variant in HashVariant::ALL {
        for (name, dag) in &scenes {
            check_load(&ctx, variant, name, dag);
        }
    }
    assert_clean(&ctx);
}

/// Random sphere / cube add / remove sequences: after every edit the voxels equal the
/// brute-force grid and the unique nodes per level equal a from-scratch canonical build.
fn random_edits(ctx: &Arc<GpuContext>, variant: HashVariant, resolution: u32, edits: usize) {
    let seed = resolution as u64 * 31 + variant.id() as u64;
    let voxels = synthetic(resolution, seed);
    let dag = Svdag::from_voxels(&voxels).unwrap();
    let mut grid = Grid::from_codes(resolution, &voxels.codes);
    let mut hd = GpuHashDag::load(ctx, &GpuHashDagConfig::new(variant, 4096), &dag, None).unwrap();
    let mut rng = common::Rng(seed ^ 0xed17);
    let n = resolution as f32;
    for step in 0..edits {
        let tool = shaped(
            if rng.below(2) == 0 {
                Shape::Sphere
            } else {
                Shape::Cube
            },
            [0, 1, 2].map(|_| rng.below(resolution as u64 * 8) as f32 / 8.0),
            1.0 + rng.below((n * 2.0) as u64) as f32 / 8.0,
            rng.below(3) == 0,
        );
        hd.edit(&tool, None).unwrap();
        grid.apply(&tool);
        let expected = grid.codes();
        let (codes, counts) = read_back(&hd);
        let what = format!("{variant:?} {resolution}^3 step {step} {tool:?}");
        assert_eq!(codes.len(), expected.len(), "{what}: voxel count");
        assert_eq!(codes, expected, "{what}: voxels");
        assert_eq!(
            counts,
            canonical_level_counts(resolution, &expected),
            "{what}: unique nodes per level"
        );
    }
    assert_eq!(hd.roots().len(), edits + 1);
}

#[test]
fn random_edits_match_brute_force_for_every_variant() {
    let ctx = common::gpu();
    for variant in HashVariant::ALL {
        random_edits(&ctx, variant, 64, 8);
    }
    random_edits(&ctx, HashVariant::AccelHash8, 128, 4);
    random_edits(&ctx, HashVariant::TicketBoard, 256, 2);
    assert_clean(&ctx);
}

#[test]
fn undo_and_redo_move_between_roots_and_a_new_edit_drops_the_redo_branch() {
    let ctx = common::gpu();
    let voxels = synthetic(32, 5);
    let dag = Svdag::from_voxels(&voxels).unwrap();
    let mut hd = GpuHashDag::load(
        &ctx,
        &GpuHashDagConfig::new(HashVariant::AccelHash8, 256),
        &dag,
        None,
    )
    .unwrap();
    let mut grid = Grid::from_codes(32, &voxels.codes);
    let mut states = vec![grid.codes()];
    assert!(!hd.undo(), "nothing to undo after a load");
    for (i, remove) in [false, true, false].into_iter().enumerate() {
        let tool = shaped(
            Shape::Sphere,
            [8.0 + 7.0 * i as f32, 16.5, 12.0],
            6.5,
            remove,
        );
        hd.edit(&tool, None).unwrap();
        grid.apply(&tool);
        states.push(grid.codes());
    }
    assert!(!hd.redo(), "nothing to redo at the newest root");
    for state in states.iter().rev().skip(1) {
        assert!(hd.undo());
        assert_eq!(&read_back(&hd).0, state);
    }
    assert!(!hd.undo());
    assert!(hd.redo());
    assert!(hd.redo());
    assert_eq!(read_back(&hd).0, states[2]);
    // A new edit from state 2 drops states 3 and 4.
    let mut grid = Grid::from_codes(32, &states[2]);
    let tool = shaped(Shape::Cube, [20.0, 20.0, 20.0], 5.0, true);
    hd.edit(&tool, None).unwrap();
    grid.apply(&tool);
    assert_eq!(hd.roots().len(), 4);
    assert!(!hd.redo());
    assert_eq!(read_back(&hd).0, grid.codes());
    assert!(hd.undo());
    assert_eq!(read_back(&hd).0, states[2]);
    drop(hd);
    assert_clean(&ctx);
}

#[test]
fn edit_on_empty_and_full_roots_and_outside_the_grid() {
    let ctx = common::gpu();
    let mut hd = GpuHashDag::new(
        &ctx,
        &GpuHashDagConfig::new(HashVariant::Atomic64, 64),
        3,
        false,
    )
    .unwrap();
    let mut grid = Grid::from_codes(32, &[]);
    let big = shaped(Shape::Cube, [16.0, 16.0, 16.0], 40.0, false);
    let tools = [
        shaped(Shape::Sphere, [10.3, 12.0, 7.5], 6.2, false),
        big,
        shaped(Shape::Sphere, [100.0, 100.0, 100.0], 3.0, true),
        shaped(Shape::Cube, [20.0, 3.0, 31.5], 2.5, true),
        shaped(Shape::Cube, [16.0, 16.0, 16.0], 40.0, true),
    ];
    for tool in &tools {
        hd.edit(tool, None).unwrap();
        grid.apply(tool);
        let (codes, _) = read_back(&hd);
        assert_eq!(codes, grid.codes(), "{tool:?}");
    }
    assert_eq!(hd.roots()[2], Root::Full(0), "the big cube fills the grid");
    assert_eq!(
        hd.roots()[3],
        Root::Full(0),
        "an edit outside changes nothing"
    );
    assert_eq!(hd.root(), Root::Empty);
    let bad = shaped(Shape::Cube, [16.0, 16.0, 16.0], f32::NAN, false);
    assert!(matches!(hd.edit(&bad, None), Err(GpuDagError::Invalid(_))));
    assert_eq!(hd.roots().len(), tools.len() + 1);
    drop(hd);
    assert_clean(&ctx);
}

/// Noise leaves (all distinct) in a pool of one super block per table and buckets so many that
/// every leaf takes its own slab: loading grows the pool (more rounds), and with the pool
/// capped at one super block, edits fail with `Exhausted` while the previous root stays intact.
#[test]
fn pool_exhaustion_grows_or_fails_with_the_previous_root_intact() {
    let ctx = common::gpu();
    let resolution = 128;
    let mut rng = common::Rng(7);
    let coords: Vec<[u32; 3]> = (0..resolution)
        .flat_map(|z| (0..resolution).flat_map(move |y| (0..72).map(move |x| [x, y, z])))
        .filter(|_| rng.below(2) == 0)
        .collect();
    let voxels = Voxels::from_coords(resolution, coords);
    let dag = Svdag::from_voxels(&voxels).unwrap();
    let config = GpuHashDagConfig {
        grow_before_insert: false,
        ..GpuHashDagConfig::new(HashVariant::TicketBoard, 1 << 20)
    };
    let grown = GpuHashDag::load(&ctx, &config, &dag, None).unwrap();
    assert!(grown.table(2).unwrap().pool().super_block_count() > 1);
    assert_eq!(read_back(&grown).0, voxels.codes);
    drop(grown);

    let capped = GpuHashDagConfig {
        max_super_blocks: 1,
        ..GpuHashDagConfig::new(HashVariant::TicketBoard, 1 << 20)
    };
    let err = GpuHashDag::load(&ctx, &capped, &dag, None).err();
    assert!(
        matches!(err, Some(GpuDagError::Hash(HashError::Exhausted { .. }))),
        "{err:?}"
    );
    // Half the noise fits; edits that make new leaves run the capped pool out.
    let half = Voxels {
        resolution,
        codes: voxels
            .codes
            .iter()
            .copied()
            .filter(|&c| morton::decode(c)[2] < 100)
            .collect(),
        colors: Vec::new(),
    };
    let mut hd =
        GpuHashDag::load(&ctx, &capped, &Svdag::from_voxels(&half).unwrap(), None).unwrap();
    let mut grid = Grid::from_codes(resolution, &half.codes);
    let mut failed = false;
    for step in 0..40 {
        let before = hd.root();
        let tool = shaped(
            Shape::Sphere,
            [
                rng.below(72) as f32 + 0.3,
                rng.below(128) as f32,
                rng.below(100) as f32,
            ],
            14.5,
            true,
        );
        match hd.edit(&tool, None) {
            Ok(_) => grid.apply(&tool),
            Err(GpuDagError::Hash(HashError::Exhausted { .. })) => {
                assert_eq!(hd.root(), before, "step {step}: root kept");
                failed = true;
            }
            Err(e) => panic!("step {step}: {e}"),
        }
        assert_eq!(read_back(&hd).0, grid.codes(), "step {step}");
        if failed {
            break;
        }
    }
    assert!(failed, "the capped pool never ran out");
    drop(hd);
    assert_clean(&ctx);
}

#[test]
fn profiled_edit_names_its_passes() {
    let ctx = common::gpu();
    let dag = Svdag::from_voxels(&synthetic(32, 3)).unwrap();
    let mut hd = GpuHashDag::load(
        &ctx,
        &GpuHashDagConfig::new(HashVariant::AccelHash32, 256),
        &dag,
        None,
    )
    .unwrap();
    let mut profiler = Profiler::new(&ctx).unwrap();
    let tool = shaped(Shape::Sphere, [20.0, 20.0, 20.0], 9.0, false);
    let report = hd.edit(&tool, Some(&mut profiler)).unwrap();
    assert_eq!(report.temporary_nodes.len(), 4);
    assert!(report.items.iter().sum::<u32>() > 0);
    if profiler.is_available() {
        let names: Vec<&str> = profiler.passes().iter().map(|p| p.name.as_str()).collect();
        for pass in [
            "edit traverse",
            "edit leaves",
            "edit build items",
            "hash insert",
        ] {
            assert!(names.contains(&pass), "{pass} missing from {names:?}");
        }
    }
    drop(profiler);
    drop(hd);
    assert_clean(&ctx);
}
