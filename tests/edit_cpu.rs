//! The CPU reference hash DAG and editor against brute force on plain voxel sets: import /
//! export round trips, random edit sequences with undo / redo / GC, deduplication completeness.

mod common;

use proptest::prelude::*;
use rustc_hash::FxHashMap;
use voxdag::dag::Svdag;
use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::item::Root;
use voxdag::edit::tool::{CopyParams, Shape, Tool, VoxelMap};
use voxdag::scene::{morton, Voxels};

/// A deterministic material per voxel, derived from its position (the imported scenes of the
/// tests have no palette).
fn material_of(v: [u32; 3]) -> u8 {
    ((v[0] / 5 + v[1] / 3 + v[2] / 7) % 16) as u8
}

/// The voxel map of an Svdag (materials from `material_of`, or 0).
fn map_of(dag: &Svdag, materials: bool) -> VoxelMap {
    let mut map = VoxelMap {
        resolution: dag.resolution,
        voxels: FxHashMap::default(),
    };
    for code in dag.to_voxels().codes {
        let v = morton::decode(code);
        map.voxels
            .insert(v, if materials { material_of(v) } else { 0 });
    }
    map
}

/// A fresh hash DAG holding `map` (built from scratch through an Svdag) and its root.
fn from_scratch(map: &VoxelMap, materials: bool, into: Option<&mut HashDag>) -> (HashDag, Root) {
    let sorted = map.sorted();
    let voxels = Voxels {
        resolution: map.resolution,
        codes: sorted.iter().map(|e| e.0).collect(),
        colors: Vec::new(),
    };
    let svdag = Svdag::from_voxels(&voxels).unwrap();
    let mats: Vec<u8> = sorted.iter().map(|e| e.1).collect();
    let mut fresh = HashDag::new(map.resolution, materials).unwrap();
    let dag = into.unwrap_or(&mut fresh);
    let root = dag
        .insert_svdag(&svdag, materials.then_some(&mats[..]))
        .unwrap();
    (dag.clone(), root)
}

/// A test scene of side `n`: empty, the teapot or the .vox model.
fn scene(kind: u8, n: u32) -> Svdag {
    let data = common::repo().join("tests/data");
    match kind {
        0 => Svdag::from_voxels(&Voxels {
            resolution: n,
            ..Default::default()
        })
        .unwrap(),
        1 => common::build_scene(&data.join("teapot.obj"), Some(n)),
        // The .vox model at its own size (its grid side, whatever `n`).
        _ => common::build_scene(&data.join("ff3.vox"), None),
    }
}

#[test]
fn import_and_export_round_trip() {
    for kind in 0..3 {
        let mut svdag = scene(kind, 64);
        svdag.colors.clear(); // geometry only: to_svdag writes no colours
        for materials in [false, true] {
            let map = map_of(&svdag, materials);
            let (dag, root) = from_scratch(&map, materials, None);
            assert_eq!(dag.voxels(root).unwrap(), map.sorted(), "scene {kind}");
            // Geometry back to an svdag: the same words as a from-scratch build.
            assert_eq!(dag.to_svdag(root).unwrap(), svdag, "scene {kind}");
            for (&v, &m) in map.voxels.iter().take(200) {
                assert_eq!(dag.voxel(root, v), Some(m));
            }
        }
    }
}

#[test]
fn full_scene_is_a_full_root() {
    let mut dag = HashDag::new(16, true).unwrap();
    let root = dag
        .edit(
            Root::Empty,
            &Tool::Add {
                shape: Shape::Cube,
                center: [8.0; 3],
                radius: 8.0,
                material: 5,
            },
        )
        .unwrap();
    assert_eq!(root, Root::Full(5));
    assert_eq!(dag.item_count(), 0);
    let svdag = dag.to_svdag(root).unwrap();
    svdag.validate().unwrap();
    assert_eq!(svdag.to_voxels().len(), 16 * 16 * 16);
    let root = dag
        .edit(
            root,
            &Tool::Remove {
                shape: Shape::Cube,
                center: [8.0; 3],
                radius: 8.0,
            },
        )
        .unwrap();
    assert_eq!(root, Root::Empty);
}

/// One step of a random session.
#[derive(Clone, Debug)]
enum Op {
    Edit(Tool),
    Undo,
    Redo,
    Gc,
    Depth(usize),
}

fn tool_strategy(n: u32) -> impl Strategy<Value = Tool> {
    let f = n as f32;
    let pos = prop::array::uniform3(-2.0f32..f + 2.0);
    let radius = 0.3f32..f / 3.0;
    let material = 0u8..16;
    prop_oneof![
        (pos.clone(), radius.clone(), material.clone(), any::<bool>()).prop_map(
            |(center, radius, material, cube)| {
                Tool::Add {
                    shape: if cube { Shape::Cube } else { Shape::Sphere },
                    center,
                    radius,
                    material,
                }
            }
        ),
        (pos.clone(), radius.clone(), any::<bool>()).prop_map(|(center, radius, cube)| {
            Tool::Remove {
                shape: if cube { Shape::Cube } else { Shape::Sphere },
                center,
                radius,
            }
        }),
        (pos.clone(), radius.clone(), material.clone()).prop_map(|(center, radius, material)| {
            Tool::Paint {
                center,
                radius,
                material,
            }
        }),
        (pos.clone(), 0.5f32..f / 4.0, material).prop_map(|(center, radius, material)| {
            Tool::Fill {
                center,
                radius,
                material,
            }
        }),
        (pos.clone(), pos.clone(), pos, 0.5f32..f / 4.0, 0usize..4).prop_map(
            |(source, dest, center, radius, t)| {
                let transform = match t {
                    0 | 1 => None,
                    2 => Some([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
                    _ => Some([[1.5, 0.0, 0.0], [0.0, 1.0, 0.2], [0.0, 0.0, -1.0]]),
                };
                Tool::Copy(CopyParams {
                    source,
                    dest,
                    center,
                    radius,
                    transform,
                })
            }
        ),
    ]
}

fn op_strategy(n: u32) -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => tool_strategy(n).prop_map(Op::Edit),
        2 => Just(Op::Undo),
        1 => Just(Op::Redo),
        1 => Just(Op::Gc),
        1 => (0usize..4).prop_map(Op::Depth),
    ]
}

/// The brute-force model of the editor: one voxel map per history entry.
struct Model {
    states: Vec<VoxelMap>,
    current: usize,
    depth: usize,
}

impl Model {
    fn trim(&mut self) {
        let excess = self.current.saturating_sub(self.depth);
        self.states.drain(..excess);
        self.current -= excess;
    }
}

fn check_session(kind: u8, n: u32, materials: bool, ops: &[Op]) {
    let svdag = scene(kind, n);
    let n = svdag.resolution;
    let start = map_of(&svdag, materials);
    let (dag, root) = from_scratch(&start, materials, None);
    let mut editor = CpuEditor::new(dag, root, 3);
    let mut model = Model {
        states: vec![start],
        current: 0,
        depth: 3,
    };
    for (step, op) in ops.iter().enumerate() {
        match op {
            Op::Edit(tool) => {
                editor.edit(tool).unwrap();
                let mut next = model.states[model.current].clone();
                next.apply(tool, materials).unwrap();
                model.states.truncate(model.current + 1);
                model.states.push(next);
                model.current += 1;
                model.trim();
            }
            Op::Undo => {
                assert_eq!(editor.undo(), model.current > 0);
                model.current = model.current.saturating_sub(1);
            }
            Op::Redo => {
                let possible = model.current + 1 < model.states.len();
                assert_eq!(editor.redo(), possible);
                model.current += possible as usize;
            }
            Op::Gc => {
                let stats = editor.gc().unwrap();
                // GC keeps exactly the canonical items of the live states: a fresh DAG holding
                // every live state has the same number of items.
                let mut all = HashDag::new(n, materials).unwrap();
                for state in &model.states {
                    let (with, _) = from_scratch(state, materials, Some(&mut all));
                    all = with;
                }
                assert_eq!(
                    editor.dag().item_count(),
                    all.item_count(),
                    "step {step}: GC kept garbage or lost items"
                );
                assert_eq!(stats.live, all.item_count());
                // Every live root still enumerates its state (undo after GC works).
                for (root, state) in editor.live_roots().iter().zip(&model.states) {
                    assert_eq!(
                        editor.dag().voxels(*root).unwrap(),
                        state.sorted(),
                        "step {step}: history after GC"
                    );
                }
            }
            Op::Depth(d) => {
                editor.set_undo_depth(*d);
                model.depth = *d;
                model.trim();
            }
        }
        assert_eq!(editor.live_roots().len(), model.states.len(), "step {step}");
        let state = &model.states[model.current];
        let got = editor.dag().voxels(editor.root()).unwrap();
        assert_eq!(
            got.len(),
            state.voxels.len(),
            "step {step} {op:?}: voxel count"
        );
        assert_eq!(got, state.sorted(), "step {step} {op:?}");
        // Deduplication is complete: unique nodes per level equal a from-scratch build's.
        let (fresh, fresh_root) = from_scratch(state, materials, None);
        assert_eq!(
            editor.unique_nodes_per_level().unwrap(),
            fresh.unique_nodes_per_level(fresh_root).unwrap(),
            "step {step} {op:?}: unique nodes per level"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn random_sessions_match_brute_force(
        kind in 0u8..3,
        materials in any::<bool>(),
        ops in prop::collection::vec(op_strategy(64), 1..10),
    ) {
        check_session(kind, 64, materials, &ops);
    }
}

#[test]
fn edits_on_a_larger_scene_match_brute_force() {
    let n = 256;
    let tools = [
        Tool::Remove {
            shape: Shape::Sphere,
            center: [128.0, 140.0, 100.0],
            radius: 40.5,
        },
        Tool::Add {
            shape: Shape::Cube,
            center: [60.2, 90.0, 128.5],
            radius: 33.0,
            material: 9,
        },
        Tool::Paint {
            center: [100.0, 120.0, 120.0],
            radius: 60.0,
            material: 2,
        },
        Tool::Copy(CopyParams {
            source: [128.0; 3],
            dest: [200.0, 60.0, 128.0],
            center: [128.0; 3],
            radius: 30.0,
            transform: None,
        }),
        Tool::Fill {
            center: [128.0, 20.0, 128.0],
            radius: 24.0,
            material: 4,
        },
    ];
    let ops: Vec<Op> = tools
        .into_iter()
        .map(Op::Edit)
        .chain([Op::Undo, Op::Gc, Op::Redo])
        .collect();
    check_session(1, n, true, &ops);
}

#[test]
fn gc_keeps_history_and_frees_the_rest() {
    let svdag = scene(1, 64);
    let map = map_of(&svdag, true);
    let (dag, root) = from_scratch(&map, true, None);
    let mut editor = CpuEditor::new(dag, root, 8);
    let before = editor.dag().item_count();
    let sphere = |x: f32| Tool::Remove {
        shape: Shape::Sphere,
        center: [x, 32.0, 32.0],
        radius: 10.0,
    };
    for i in 0..4 {
        editor.edit(&sphere(10.0 + 12.0 * i as f32)).unwrap();
    }
    assert!(editor.dag().item_count() > before);
    let first_edit = editor.live_roots()[1];
    let Root::Node(first_ptr) = first_edit else {
        panic!("teapot root is a node")
    };
    editor.gc().unwrap();
    assert!(
        editor.dag().is_stored(first_ptr),
        "an undo step survives GC"
    );
    let expected: Vec<_> = editor
        .live_roots()
        .iter()
        .map(|r| editor.dag().voxels(*r).unwrap())
        .collect();
    // Undo everything, make a new edit: the redo branch goes, GC frees its items.
    while editor.undo() {}
    assert_eq!(editor.dag().voxels(editor.root()).unwrap(), expected[0]);
    editor.redo();
    assert_eq!(editor.dag().voxels(editor.root()).unwrap(), expected[1]);
    let last = *editor.live_roots().last().unwrap();
    editor.edit(&sphere(50.0)).unwrap();
    assert_eq!(editor.redo_steps(), 0);
    let stats = editor.gc().unwrap();
    assert!(stats.freed > 0, "the dropped redo branch is freed");
    if let Root::Node(ptr) = last {
        assert!(
            !editor.dag().is_stored(ptr),
            "the dropped branch's root is freed"
        );
    }
    // Nothing left to free.
    assert_eq!(editor.gc().unwrap().freed, 0);
}

#[test]
fn failed_edit_changes_nothing() {
    let svdag = scene(1, 64);
    let map = map_of(&svdag, false);
    let (dag, root) = from_scratch(&map, false, None);
    let mut editor = CpuEditor::new(dag, root, 8);
    let items = editor.dag().item_count();
    let bad = Tool::Add {
        shape: Shape::Sphere,
        center: [f32::NAN, 0.0, 0.0],
        radius: 3.0,
        material: 0,
    };
    assert!(editor.edit(&bad).is_err());
    assert_eq!(editor.dag().item_count(), items);
    assert_eq!(editor.live_roots(), &[root]);
}

#[test]
fn full_table_fails_the_edit_and_keeps_the_previous_root() {
    let svdag = scene(1, 64);
    let map = map_of(&svdag, true);
    let (mut dag, root) = from_scratch(&map, true, None);
    let used = dag.item_count() as u32;
    // Room for only a few new items: a large edit cannot finish.
    dag.set_item_limit(used / 4);
    let mut editor = CpuEditor::new(dag, root, 8);
    let tool = Tool::Paint {
        center: [32.0; 3],
        radius: 30.0,
        material: 3,
    };
    let err = editor.edit(&tool).unwrap_err();
    assert!(err.to_string().contains("is full"), "{err}");
    assert_eq!(editor.dag().item_count() as u32, used);
    assert_eq!(editor.live_roots(), &[root]);
    assert_eq!(editor.dag().voxels(editor.root()).unwrap(), map.sorted());
    // GC after the failed edit keeps the scene.
    editor.gc().unwrap();
    assert_eq!(editor.dag().voxels(editor.root()).unwrap(), map.sorted());
}
