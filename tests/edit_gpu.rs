//! The GPU hash DAG (engine/edit/gpu.rs) on a real device (lavapipe in CI): loading svdag32
//! scenes into the nine per-size tables and reading them back, the sphere / cube edit pipeline
//! against a brute-force edit of a plain voxel grid, deduplication completeness against a CPU
//! canonical build, and pool exhaustion during an edit. Every variant of the tables; every test
//! ends with zero validation messages and zero live allocations.

mod common;

use std::sync::Arc;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use rustc_hash::FxHashMap;
use voxdag::dag::Svdag;
use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::gpu::{table_buckets, GpuDagError, GpuHashDag, GpuHashDagConfig};
use voxdag::edit::item::Root;
use voxdag::edit::tool::{self, CopyParams, Shape, Tool, VoxelMap};
use voxdag::edit::walk;
use voxdag::gpu::{GpuContext, Profiler};
use voxdag::hash::{HashError, HashVariant, TeamMode};
use voxdag::scene::{morton, Voxels};

fn assert_clean(ctx: &Arc<GpuContext>) {
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

/// Unique canonical nodes per level (index = level) of a geometry-only voxel set.
fn canonical_level_counts(resolution: u32, codes: &[u64]) -> Vec<u64> {
    let voxels: Vec<(u64, u8)> = codes.iter().map(|&c| (c, 0)).collect();
    canonical_counts(resolution, &voxels)
}

/// Unique canonical nodes per level (index = level) of a voxel set with materials, built
/// bottom-up from scratch on the CPU the way the hash DAG stores them (a leaf or node that is
/// full of one material is a value in its parent, not a node).
fn canonical_counts(resolution: u32, voxels: &[(u64, u8)]) -> Vec<u64> {
    const EMPTY: u64 = u64::MAX;
    let full = |m: u8| u64::MAX - 1 - m as u64;
    let is_full = |v: u64| v != EMPTY && v >= u64::MAX - 16;
    let root_level = resolution.trailing_zeros() - 2;
    let mut leaves: FxHashMap<u64, (u64, [u8; 64])> = FxHashMap::default();
    for &(c, m) in voxels {
        let leaf = leaves.entry(c >> 6).or_insert((0, [0; 64]));
        leaf.0 |= 1 << (c & 63);
        leaf.1[(c & 63) as usize] = m;
    }
    let mut values: FxHashMap<u64, u64> = FxHashMap::default();
    let mut ids: FxHashMap<Vec<u64>, u64> = FxHashMap::default();
    for (&at, (mask, materials)) in &leaves {
        let value = if *mask == u64::MAX && materials.iter().all(|&m| m == materials[0]) {
            full(materials[0])
        } else {
            let mut key = vec![*mask];
            key.extend(materials.iter().map(|&m| m as u64));
            let next = ids.len() as u64;
            *ids.entry(key).or_insert(next)
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
            let value = if is_full(children[0]) && children.iter().all(|&c| c == children[0]) {
                children[0]
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
    random_edits_with(ctx, GpuHashDagConfig::new(variant, 4096), resolution, edits);
}

fn random_edits_with(
    ctx: &Arc<GpuContext>,
    config: GpuHashDagConfig,
    resolution: u32,
    edits: usize,
) {
    let variant = config.variant;
    let seed = resolution as u64 * 31 + variant.id() as u64;
    let voxels = synthetic(resolution, seed);
    let dag = Svdag::from_voxels(&voxels).unwrap();
    let mut grid = Grid::from_codes(resolution, &voxels.codes);
    let mut hd = GpuHashDag::load(ctx, &config, &dag, None).unwrap();
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

/// Tables sized by the load (`Buckets::FromLoad`): each table's buckets follow the items the
/// scene's nodes make in it (an inner node of c children has 1 + c words, a leaf 2), the load
/// holds the scene in fewer slab bytes than the largest of those counts in every table, and
/// edits on them stay exact.
#[test]
fn tables_sized_by_the_load_follow_their_items_and_edit_exactly() {
    let ctx = common::gpu();
    let dag = Svdag::from_voxels(&synthetic(256, 5)).unwrap();
    let mut loaded = [0u64; 9];
    loaded[0] = dag.level_range(0).len() as u64 / 2;
    for level in 1..=dag.root_level() {
        let mut at = dag.level_range(level).start;
        while at < dag.level_range(level).end {
            let children = dag.words[at].count_ones() as usize;
            loaded[children - 1] += 1;
            at += 1 + children;
        }
    }
    let buckets = table_buckets(&loaded);
    assert!(buckets.iter().any(|&b| b != buckets[0]), "{buckets:?}");
    let sized = GpuHashDagConfig::sized_by_load(HashVariant::TicketBoard);
    let mut hd = GpuHashDag::load(&ctx, &sized, &dag, None).unwrap();
    assert_eq!(hd.buckets(), buckets);
    let most = *buckets.iter().max().unwrap();
    let mut uniform = GpuHashDag::load(
        &ctx,
        &GpuHashDagConfig::new(HashVariant::TicketBoard, most),
        &dag,
        None,
    )
    .unwrap();
    let (a, b) = (hd.gc(None).unwrap(), uniform.gc(None).unwrap());
    assert_eq!(a.live_per_table, b.live_per_table);
    assert!(
        a.slab_bytes_after < b.slab_bytes_after,
        "{} >= {} slab bytes",
        a.slab_bytes_after,
        b.slab_bytes_after
    );
    drop((hd, uniform));
    for variant in HashVariant::ALL {
        random_edits_with(&ctx, GpuHashDagConfig::sized_by_load(variant), 64, 4);
    }
    assert_clean(&ctx);
}

/// A large sphere: the top levels have few nodes (one dispatch of one SIMD group traverses
/// them, `edit/traverse_small_levels.comp`, and one merges them, `edit/merge_small_levels.comp`),
/// the lower levels more (their own passes); the voxels and the unique nodes per level equal
/// the brute force's, and the temporary nodes per level those of a traversal one level per
/// submission (no level traversed twice: by the chain and by its own dispatch).
#[test]
fn large_edit_fuses_the_small_levels_and_dispatches_the_large_ones() {
    let ctx = common::gpu();
    let resolution = 256;
    let voxels = synthetic(resolution, 77);
    let dag = Svdag::from_voxels(&voxels).unwrap();
    let mut grid = Grid::from_codes(resolution, &voxels.codes);
    let config = GpuHashDagConfig::new(HashVariant::Atomic64, 4096);
    let mut hd = GpuHashDag::load(&ctx, &config, &dag, None).unwrap();
    let per_submission = GpuHashDagConfig {
        traversal_budget: 0,
        ..config.clone()
    };
    let mut level_by_level = GpuHashDag::load(&ctx, &per_submission, &dag, None).unwrap();
    let mut profiler = Profiler::new(&ctx).unwrap();
    for (center, radius, remove) in [
        ([128.3, 120.0, 131.5], 90.0, false),
        ([60.0, 200.0, 90.0], 70.0, true),
    ] {
        let tool = shaped(Shape::Sphere, center, radius, remove);
        profiler.clear();
        let report = hd.edit(&tool, Some(&mut profiler)).unwrap();
        let per_level = &report.temporary_nodes;
        let expected = level_by_level.edit(&tool, None).unwrap().temporary_nodes;
        assert_eq!(per_level, &expected, "temporary nodes per level");
        // Some levels small enough for the chain of small levels (at most 128 nodes:
        // `MAX_NODES` in engine/edit/gpu/small_levels.rs), some larger.
        assert!(
            per_level.iter().any(|&n| n > 1 && n <= 128),
            "{per_level:?}"
        );
        assert!(per_level.iter().any(|&n| n > 128), "{per_level:?}");
        if profiler.is_available() {
            // The small top levels in one dispatch, the large ones' passes of their own.
            let calls = |name: &str| profiler.passes().iter().filter(|p| p.name == name).count();
            let chained = per_level.iter().rposition(|&n| n > 128).unwrap() + 1;
            let own = per_level[..chained].iter().filter(|&&n| n > 0).count();
            assert_eq!(calls("edit merge small levels"), 1, "{per_level:?}");
            // The traversal's first level only in the dispatch of its small levels, and the
            // inner levels below it there too while the tool's bounds (at most 8x the level
            // above) keep them within the chain's 128 entries: no dispatch of their own.
            let inner = per_level.iter().skip(1).filter(|&&n| n > 0).count();
            let bounds = voxdag::edit::gpu::traversal_bounds(center, radius, hd.root_level());
            let top = per_level.len() - 1;
            let mut cap = 1;
            let surely_chained = (1..top)
                .rev()
                .take_while(|&l| {
                    cap = bounds[l].min(8 * cap);
                    cap <= 128
                })
                .count();
            assert_eq!(calls("edit traverse small levels"), 1, "{per_level:?}");
            assert_eq!(
                calls("edit traverse"),
                inner - 1 - surely_chained,
                "{per_level:?} {bounds:?}"
            );
            assert_eq!(calls("edit build items"), own, "{per_level:?}");
        }
        grid.apply(&tool);
        let expected = grid.codes();
        let (codes, counts) = read_back(&hd);
        assert_eq!(codes, expected, "{tool:?}: voxels");
        assert_eq!(
            counts,
            canonical_level_counts(resolution, &expected),
            "{tool:?}: unique nodes per level"
        );
    }
    drop(profiler);
    drop(hd);
    drop(level_by_level);
    assert_clean(&ctx);
}

/// The traversal's other submission plans give the same edits: one level per submission with
/// exact capacities (budget 0, also the fallback after a wrong bound) and levels split over
/// several submissions by a tiny budget (the last level's count read back between them).
#[test]
fn random_edits_match_brute_force_with_every_traversal_budget() {
    let ctx = common::gpu();
    for budget in [0, 4 << 10] {
        let mut config = GpuHashDagConfig::new(HashVariant::AccelHash32, 4096);
        config.traversal_budget = budget;
        random_edits_with(&ctx, config, 128, 6);
    }
    assert_clean(&ctx);
}

/// The dissertation's route (subgroup teams: the dedup table and `mark`) and the default
/// single-lane route (the tables' claim passes) give the same scenes.
#[test]
fn random_edits_match_brute_force_with_either_team_mode() {
    let ctx = common::gpu();
    for (variant, team) in [
        (HashVariant::AccelHash32, TeamMode::Subgroup),
        (HashVariant::Atomic64, TeamMode::Subgroup),
        (HashVariant::TicketBoard, TeamMode::SingleLane),
    ] {
        let config = GpuHashDagConfig {
            team,
            ..GpuHashDagConfig::new(variant, 4096)
        };
        random_edits_with(&ctx, config, 128, 5);
    }
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

/// Saving and counting walk the DAG item by item, never voxel by voxel: at 65536^3 the grid
/// filled with material 3 and then a small sphere removed (2^48 voxels less a few hundred:
/// petabytes as a voxel list) converts to the CPU editor's svdag32 DAG, with its unique items
/// per level and its voxels per material.
#[test]
fn a_filled_grid_converts_and_counts_by_items_not_voxels() {
    let ctx = common::gpu();
    let root_level = 14;
    let center = [1000.5, 2000.0, 3000.25];
    let tools = [
        Tool::Add {
            shape: Shape::Cube,
            center: [32768.0; 3],
            radius: 40000.0,
            material: 3,
        },
        Tool::Remove {
            shape: Shape::Sphere,
            center,
            radius: 6.0,
        },
    ];
    let config = GpuHashDagConfig::new(HashVariant::Atomic64, 1024);
    let mut hd = GpuHashDag::new(&ctx, &config, root_level, true).unwrap();
    let mut cpu = CpuEditor::new(HashDag::new(4 << root_level, true).unwrap(), Root::Empty, 4);
    for tool in &tools {
        hd.edit(tool, None).unwrap();
        cpu.edit(tool).unwrap();
    }
    let image = hd.download().unwrap();
    let root = hd.root();
    assert!(matches!(root, Root::Node(_)));
    assert_eq!(
        image.to_svdag(root).unwrap(),
        cpu.dag().to_svdag(cpu.root()).unwrap()
    );
    assert_eq!(
        image.level_counts(root).unwrap(),
        cpu.unique_nodes_per_level().unwrap()
    );
    let mut removed = 0u64;
    for z in 2990..3010 {
        for y in 1990..2010 {
            for x in 990..1010 {
                removed += tool::in_sphere(center, 6.0, [x, y, z]) as u64;
            }
        }
    }
    let mut expected = [0u64; 16];
    expected[3] = (1u64 << 48) - removed;
    let per_material = walk::voxels_per_material(&image, root, &mut FxHashMap::default());
    assert_eq!(per_material.unwrap(), expected);
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

/// A recorded merge reserves each table for its share of the level's items. On a scene of
/// scattered voxels (nodes of one child) a solid sphere makes far more 8-child nodes than the
/// tables' shares say: it runs a pool out and merges once more on pools grown for the items
/// it built (two merge chains in one edit, none level by level), with the CPU editor's
/// result; the next sphere fits at once.
#[test]
fn a_merge_that_runs_a_pool_out_reserves_again_for_what_it_built() {
    let ctx = common::gpu();
    let mut codes: Vec<u64> = (1..5_000u64)
        .map(|i| i.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 31)
        .collect();
    codes.sort_unstable();
    codes.dedup();
    let scene = Voxels {
        resolution: 2048,
        codes,
        colors: Vec::new(),
    };
    let svdag = Svdag::from_voxels(&scene).unwrap();
    // Buckets enough for every new item to open a chain of its own.
    let config = GpuHashDagConfig::new(HashVariant::Atomic64, 1 << 20);
    let mut hd = GpuHashDag::load(&ctx, &config, &svdag, None).unwrap();
    let mut dag = HashDag::new(2048, false).unwrap();
    let root = dag.insert_svdag(&svdag, None).unwrap();
    let mut cpu = CpuEditor::new(dag, root, 4);
    let mut profiler = Profiler::new(&ctx).unwrap();
    let mut chains = Vec::new();
    for center in [[900.3, 1020.0, 1010.5], [1150.0, 1040.5, 1030.0]] {
        let tool = shaped(Shape::Sphere, center, 700.0, false);
        let from = profiler.passes().len();
        hd.edit(&tool, Some(&mut profiler)).unwrap();
        cpu.edit(&tool).unwrap();
        let image = hd.download().unwrap();
        let expected = cpu.dag().to_svdag(cpu.root()).unwrap();
        assert_eq!(image.to_svdag(hd.root()).unwrap(), expected, "{tool:?}");
        let passes = &profiler.passes()[from..];
        chains.push(
            passes
                .iter()
                .filter(|p| p.name == "edit merge small levels")
                .count(),
        );
    }
    if profiler.is_available() {
        assert_eq!(chains, [2, 1], "merge chains per edit");
    }
    drop(profiler);
    drop(hd);
    assert_clean(&ctx);
}

/// Pipelines made after the load (`prepare_tools` for the tools, `prepare_gc` for the
/// collection) leave none to make in the edits and the collection that follow: no first stroke
/// or first automatic GC stalls on compiles (lavapipe: ~20 ms each).
#[test]
fn prepared_pipelines_leave_none_to_the_edits_and_the_gc() {
    let ctx = common::gpu();
    let dag = Svdag::from_voxels(&synthetic(64, 5)).unwrap();
    let config = GpuHashDagConfig::new(HashVariant::TicketBoard, 1024);
    let mut hd = GpuHashDag::load(&ctx, &config, &dag, None).unwrap();
    let tools = [
        shaped(Shape::Sphere, [30.0, 30.0, 30.0], 12.0, false),
        shaped(Shape::Cube, [20.0, 40.0, 30.0], 6.0, true),
        Tool::Fill {
            center: [32.0, 32.0, 32.0],
            radius: 10.0,
            material: 0,
        },
        Tool::Copy(CopyParams {
            source: [16.0, 16.0, 16.0],
            dest: [44.0, 40.0, 20.0],
            center: [16.0, 16.0, 16.0],
            radius: 8.0,
            transform: None,
        }),
    ];
    hd.prepare_tools(&tools).unwrap();
    hd.prepare_gc().unwrap();
    let made = ctx.pipelines_created();
    assert!(made > 0);
    // Warmed too: no pipeline's first dispatch (llvmpipe's native compile) is left to them.
    let first = ctx.first_dispatches();
    for tool in &tools {
        hd.edit(tool, None).unwrap();
    }
    hd.gc(None).unwrap();
    assert_eq!(
        ctx.pipelines_created(),
        made,
        "pipelines made by the edits or the GC"
    );
    assert_eq!(
        ctx.first_dispatches(),
        first,
        "pipelines first dispatched by the edits or the GC"
    );
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
        // Every level of this small scene is small, and the tool's bounds say so before the
        // edit: one dispatch traverses the inner levels (no dispatch of their own), one merges
        // them all.
        for pass in [
            "edit traverse small levels",
            "edit leaves",
            "edit merge small levels",
        ] {
            assert!(names.contains(&pass), "{pass} missing from {names:?}");
        }
        for pass in [
            "edit traverse",
            "edit build items",
            "hash search, claim and insert",
        ] {
            assert!(!names.contains(&pass), "{pass} in {names:?}");
        }
    }
    drop(profiler);
    drop(hd);
    assert_clean(&ctx);
}

/// One step of an edit sequence.
#[derive(Clone, Debug)]
enum Step {
    Edit(Tool),
    Undo,
    Redo,
}

/// A starting scene of the sequences.
struct Scene {
    name: &'static str,
    resolution: u32,
    materials: bool,
    /// Imported geometry (loaded with `GpuHashDag::load`); None: an empty scene.
    dag: Option<Svdag>,
    variant: HashVariant,
    /// Largest tool radius in voxels (keeps the brute-force reference fast).
    max_radius: u32,
    /// `GpuHashDagConfig::word_views`.
    word_views: bool,
}

/// Copy transforms the sequences draw from (None = identity).
fn transforms() -> [Option<[[f32; 3]; 3]>; 5] {
    [
        None,
        Some([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
        Some([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
        Some([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
        Some([[1.5, 0.0, 0.0], [0.0, 0.7, 0.2], [0.0, 0.0, 0.5]]),
    ]
}

/// Random steps: every tool (positions a little beyond the grid on quarter voxels, radii on
/// eighths, any material, a copy transform from `transforms`), undo and redo.
fn steps(resolution: u32, max_radius: u32, len: usize) -> impl Strategy<Value = Vec<Step>> {
    let n = resolution as i32;
    let pos =
        move || prop::array::uniform3(-16..4 * n + 16).prop_map(|a| a.map(|x| x as f32 / 4.0));
    let step = (
        0u32..13,
        pos(),
        pos(),
        pos(),
        2..8 * max_radius,
        0u8..16,
        0usize..5,
    )
        .prop_map(|(kind, a, b, c, r, material, t)| {
            let radius = r as f32 / 8.0;
            let shape = if kind % 2 == 0 {
                Shape::Sphere
            } else {
                Shape::Cube
            };
            Step::Edit(match kind {
                0..=2 => Tool::Add {
                    shape,
                    center: a,
                    radius,
                    material,
                },
                3 | 4 => Tool::Remove {
                    shape,
                    center: a,
                    radius,
                },
                5 => Tool::Paint {
                    center: a,
                    radius,
                    material,
                },
                6 | 7 => Tool::Fill {
                    center: a,
                    radius,
                    material,
                },
                8 | 9 => Tool::Copy(CopyParams {
                    source: b,
                    dest: c,
                    center: a,
                    radius,
                    transform: transforms()[t],
                }),
                10 => return Step::Undo,
                11 => return Step::Redo,
                _ => Tool::Add {
                    shape: Shape::Cube,
                    center: a,
                    radius,
                    material,
                },
            })
        });
    prop::collection::vec(step, 1..=len)
}

/// Runs `steps` on the GPU hash DAG, the CPU reference editor and a brute-force `VoxelMap`
/// (with its own history); after every step the voxels and materials of all three and the GPU
/// undo / redo answers agree, and the GPU's unique nodes per level equal a canonical build
/// from scratch.
fn check_sequence(ctx: &Arc<GpuContext>, scene: &Scene, steps: &[Step]) {
    let n = scene.resolution;
    let config = GpuHashDagConfig {
        word_views: scene.word_views,
        ..GpuHashDagConfig::new(scene.variant, 1024)
    };
    let (mut hd, cpu_dag, cpu_root, map) = match &scene.dag {
        Some(dag) => {
            let mut cpu = HashDag::new(n, scene.materials).unwrap();
            let root = cpu.insert_svdag(dag, None).unwrap();
            let mut map = VoxelMap {
                resolution: n,
                voxels: FxHashMap::default(),
            };
            for c in dag.to_voxels().codes {
                map.voxels.insert(morton::decode(c), 0);
            }
            (
                GpuHashDag::load(ctx, &config, dag, None).unwrap(),
                cpu,
                root,
                map,
            )
        }
        None => {
            let root_level = n.trailing_zeros() - 2;
            (
                GpuHashDag::new(ctx, &config, root_level, scene.materials).unwrap(),
                HashDag::new(n, scene.materials).unwrap(),
                Root::Empty,
                VoxelMap {
                    resolution: n,
                    voxels: FxHashMap::default(),
                },
            )
        }
    };
    assert_eq!(hd.with_materials(), scene.materials);
    let mut cpu = CpuEditor::new(cpu_dag, cpu_root, usize::MAX);
    let mut history = vec![map];
    let mut current = 0;
    for (i, step) in steps.iter().enumerate() {
        let what = format!("{} step {i} {step:?}", scene.name);
        match step {
            Step::Edit(tool) => {
                hd.edit(tool, None)
                    .unwrap_or_else(|e| panic!("{what}: GPU edit: {e}"));
                cpu.edit(tool).unwrap();
                let mut map = history[current].clone();
                map.apply(tool, scene.materials).unwrap();
                history.truncate(current + 1);
                history.push(map);
                current += 1;
            }
            Step::Undo => {
                let moved = current > 0;
                current -= moved as usize;
                assert_eq!(hd.undo(), moved, "{what}");
                assert_eq!(cpu.undo(), moved, "{what}");
            }
            Step::Redo => {
                let moved = current + 1 < history.len();
                current += moved as usize;
                assert_eq!(hd.redo(), moved, "{what}");
                assert_eq!(cpu.redo(), moved, "{what}");
            }
        }
        let expected = history[current].sorted();
        let image = hd.download().unwrap();
        let gpu = image.voxels(hd.root()).unwrap();
        assert_eq!(
            cpu.dag().voxels(cpu.root()).unwrap(),
            expected,
            "{what}: CPU editor vs brute force"
        );
        assert_eq!(gpu.len(), expected.len(), "{what}: voxel count");
        assert_eq!(gpu, expected, "{what}: GPU voxels and materials");
        assert_eq!(
            image.level_counts(hd.root()).unwrap(),
            canonical_counts(n, &expected),
            "{what}: unique nodes per level"
        );
    }
}

/// Cases per scene: `VOXDAG_EDIT_CASES` (default 3, sized for 2 loaded cores).
fn cases() -> u32 {
    std::env::var("VOXDAG_EDIT_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3)
}

#[test]
fn random_tool_sequences_match_the_cpu_editor_and_brute_force() {
    let ctx = common::gpu();
    let scenes = [
        Scene {
            name: "empty 64 with materials",
            resolution: 64,
            materials: true,
            dag: None,
            variant: HashVariant::AccelHash8,
            max_radius: 16,
            word_views: true,
        },
        Scene {
            name: "teapot 64",
            resolution: 64,
            materials: false,
            dag: Some(common::build_scene(
                &common::repo().join("tests/data/teapot.obj"),
                Some(64),
            )),
            variant: HashVariant::TicketBoard,
            max_radius: 16,
            // build_items through addresses (as for buffers beyond a word view).
            word_views: false,
        },
        Scene {
            name: "synthetic 128",
            resolution: 128,
            materials: false,
            dag: Some(Svdag::from_voxels(&synthetic(128, 11)).unwrap()),
            variant: HashVariant::Atomic64,
            max_radius: 12,
            word_views: true,
        },
        Scene {
            name: "empty 256 with materials",
            resolution: 256,
            materials: true,
            dag: None,
            variant: HashVariant::AccelHash32,
            max_radius: 12,
            word_views: true,
        },
    ];
    for scene in &scenes {
        let mut runner = TestRunner::new(Config {
            cases: cases(),
            failure_persistence: None,
            max_shrink_iters: 16,
            ..Config::default()
        });
        runner
            .run(&steps(scene.resolution, scene.max_radius, 8), |steps| {
                check_sequence(&ctx, scene, &steps);
                Ok(())
            })
            .unwrap_or_else(|e| panic!("{}: {e}", scene.name));
    }
    assert_clean(&ctx);
}

/// Fixed cases the random sequences rarely hit: a fill walled in on one side (and one started
/// on a solid voxel), paint over full nodes of another material, a copy with a mirror onto a
/// partly solid destination, leaves of several materials edited in part, in a 32^3 scene with
/// materials.
#[test]
fn fixed_tool_cases_match_the_cpu_editor_and_brute_force() {
    let ctx = common::gpu();
    let add = |shape, center, radius, material| {
        Step::Edit(Tool::Add {
            shape,
            center,
            radius,
            material,
        })
    };
    let paint = |center, radius, material| {
        Step::Edit(Tool::Paint {
            center,
            radius,
            material,
        })
    };
    let steps = vec![
        add(Shape::Cube, [16.0, 16.0, 16.0], 40.0, 2),
        Step::Edit(Tool::Remove {
            shape: Shape::Cube,
            center: [8.0, 16.0, 16.0],
            radius: 6.0,
        }),
        add(Shape::Cube, [8.0, 16.0, 16.0], 0.5, 5),
        Step::Edit(Tool::Fill {
            center: [4.5, 16.5, 16.5],
            radius: 9.0,
            material: 7,
        }),
        Step::Undo,
        Step::Edit(Tool::Fill {
            center: [8.5, 16.5, 16.5],
            radius: 3.0,
            material: 9,
        }),
        paint([24.0, 8.0, 8.0], 11.0, 3),
        Step::Edit(Tool::Remove {
            shape: Shape::Sphere,
            center: [24.0, 24.0, 24.0],
            radius: 7.5,
        }),
        Step::Edit(Tool::Copy(CopyParams {
            source: [8.0, 8.0, 8.0],
            dest: [24.0, 24.0, 24.0],
            center: [10.0, 10.0, 8.0],
            radius: 6.0,
            transform: transforms()[1],
        })),
        Step::Undo,
        Step::Redo,
        // Leaves of three materials, then edits that keep part of a leaf: the kept voxels take
        // their materials by rank in the stored leaf.
        paint([5.0, 5.0, 5.0], 2.0, 4),
        paint([6.5, 6.5, 6.5], 1.5, 6),
        Step::Edit(Tool::Remove {
            shape: Shape::Sphere,
            center: [4.0, 4.0, 4.0],
            radius: 1.2,
        }),
        paint([7.0, 4.0, 4.0], 2.0, 9),
        paint([16.0, 16.0, 16.0], 100.0, 1),
    ];
    for (name, materials, variant, word_views) in [
        (
            "fixed 32 with materials",
            true,
            HashVariant::TicketBoard,
            true,
        ),
        ("fixed 32", false, HashVariant::Atomic64, true),
        (
            "fixed 32 with materials, through addresses",
            true,
            HashVariant::Atomic64,
            false,
        ),
    ] {
        let scene = Scene {
            name,
            resolution: 32,
            materials,
            dag: None,
            variant,
            max_radius: 0,
            word_views,
        };
        check_sequence(&ctx, &scene, &steps);
    }
    assert_clean(&ctx);
}

/// The edit's traversal runs its levels in one submission and the auto-GC check reads no
/// status (the pool use read with the previous root). Single lanes (lavapipe) record the whole
/// merge without waiting between levels: two waits in all. The subgroup route waits once per
/// level (the size counters of the next level are read with the table passes of this one):
/// one wait per level with temporary nodes, plus the traversal's, the first level's counters
/// and the root's. Printed for docs/editing-gpu.md.
#[test]
fn an_edit_waits_twice_or_once_per_level_plus_two() {
    let ctx = common::gpu();
    let dag = Svdag::from_voxels(&synthetic(64, 9)).unwrap();
    let mut hd = GpuHashDag::load(
        &ctx,
        &GpuHashDagConfig::new(HashVariant::TicketBoard, 1024),
        &dag,
        None,
    )
    .unwrap();
    for tool in [
        shaped(Shape::Sphere, [40.0, 30.0, 31.0], 12.0, false),
        shaped(Shape::Sphere, [40.0, 30.0, 31.0], 12.0, true),
        shaped(Shape::Cube, [20.0, 40.0, 10.0], 6.0, false),
    ] {
        let before = ctx.stats();
        let report = hd.edit(&tool, None).unwrap();
        let stats = ctx.stats().since(before);
        let levels = report.temporary_nodes.iter().filter(|&&n| n > 0).count() as u64;
        println!(
            "host waits: {} and submissions: {} for {levels} levels {:?}",
            stats.host_waits, stats.submissions, report.items
        );
        assert_eq!(report.retried_rounds, 0);
        let single_lanes = hd.table(2).unwrap().team_size() == 1;
        let most = if single_lanes { 2 } else { levels + 2 };
        assert!(
            stats.host_waits <= most,
            "{} host waits for {levels} levels",
            stats.host_waits
        );
    }
    drop(hd);
    assert_clean(&ctx);
}

/// `edit_cube_all_outside` of `edit/common.glsl` in f32, the test the traverse pass
/// subdivides by.
fn all_outside(p: [u32; 3], side: u32, c: [f32; 3], r: f32, cube: bool) -> bool {
    let r = r + 1.0;
    let lo = p.map(|x| x as f32);
    let hi = p.map(|x| (x + side) as f32);
    if cube {
        return (0..3).any(|a| hi[a] < c[a] - r || lo[a] > c[a] + r);
    }
    let d: f32 = (0..3)
        .map(|a| (lo[a] - c[a]).max(c[a] - hi[a]).max(0.0))
        .map(|d| d * d)
        .sum();
    d > r * r
}

/// Every cube the traverse pass can subdivide is counted by the bound, for spheres and
/// cubes at assorted positions (inside, on the border, outside the grid) and radii.
#[test]
fn traversal_bounds_cover_every_cube_not_outside_the_region() {
    let root_level = 4; // 64^3
    let n = 4u32 << root_level;
    let mut seed = 7u32;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 17;
        seed ^= seed << 5;
        seed
    };
    for case in 0..200 {
        let c = [0; 3].map(|_| (next() % (4 * (n + 16))) as f32 / 4.0 - 8.0);
        let r = (next() % 320) as f32 / 8.0 + 0.125;
        let cube = case % 2 == 0;
        let bounds = voxdag::edit::gpu::traversal_bounds(c, r, root_level);
        for (level, &bound) in bounds.iter().enumerate() {
            let side = 4u32 << level;
            let cells = n / side;
            let mut reached = 0u64;
            for z in 0..cells {
                for y in 0..cells {
                    for x in 0..cells {
                        let p = [x, y, z].map(|k| k * side);
                        reached += !all_outside(p, side, c, r, cube) as u64;
                    }
                }
            }
            assert!(
                reached <= bound,
                "level {level}: {reached} cubes > bound {bound} (centre {c:?}, radius {r})"
            );
        }
    }
}
