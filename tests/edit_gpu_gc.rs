//! GC and history of the GPU hash DAG (engine/edit/gpu_gc.rs) on a real device (lavapipe in
//! CI): after edits, undos and collections every kept root still reads back the CPU reference
//! editor's voxels; the items stored after a collection are exactly the unique items reachable
//! from the live roots, per table, used as leaves and nodes as the CPU editor's items are after
//! the same sequence and its GC (which keeps exactly its reachable items); a tiny pool runs a
//! long edit sequence with automatic GC and runs out without.

mod common;

use std::sync::Arc;

use rustc_hash::FxHashSet;
use voxdag::dag::Svdag;
use voxdag::edit::cpu::{CpuEditor, HashDag};
use voxdag::edit::gpu::{GpuDagError, GpuHashDag, GpuHashDagConfig, HashDagImage};
use voxdag::edit::item::{InnerNode, NodePtr, Root, TABLE_COUNT};
use voxdag::edit::tool::{Shape, Tool};
use voxdag::gpu::{GpuContext, Profiler};
use voxdag::hash::{HashError, HashVariant};
use voxdag::scene::Voxels;

fn assert_clean(ctx: &Arc<GpuContext>) {
    ctx.wait_idle().unwrap();
    assert_eq!(ctx.live_allocations(), 0, "leaked GPU allocations");
    assert_eq!(ctx.validation_errors(), 0, "validation messages (see log)");
}

/// Applies a tool on the GPU.
fn gpu_edit(hd: &mut GpuHashDag, tool: &Tool) -> Result<(), GpuDagError> {
    hd.edit(tool, None).map(|_| ())
}

/// A random add / remove sphere or cube inside a grid of side `n`.
fn random_tool(rng: &mut common::Rng, n: u32) -> Tool {
    let shape = if rng.below(2) == 0 {
        Shape::Sphere
    } else {
        Shape::Cube
    };
    let center = [0, 1, 2].map(|_| rng.below(n as u64 * 8) as f32 / 8.0);
    let radius = 1.0 + rng.below(n as u64 * 2) as f32 / 8.0;
    if rng.below(3) == 0 {
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

/// What `roots` reach, per table: distinct items, and distinct uses (item, leaf or node).
/// A leaf (its 64-bit mask) and a one-child node (header and handle) with the same words are
/// one item, shared; whether a node's words equal some leaf's depends on handle values, which
/// the GPU allocates in a nondeterministic order, so the GPU and CPU editors agree on the uses
/// but not always on the items (one GPU item fewer in about one run in eight, before this split).
struct Reachable {
    items: Vec<u64>,
    uses: Vec<u64>,
}

/// [`Reachable`] from `roots`; `children(ptr)` names an inner node's node children.
fn reachable_per_table(
    roots: &[Root],
    root_level: u32,
    children: impl Fn(NodePtr) -> Vec<NodePtr>,
) -> Reachable {
    let mut seen: FxHashSet<NodePtr> = FxHashSet::default();
    let mut uses: FxHashSet<(NodePtr, bool)> = FxHashSet::default();
    let mut expanded: FxHashSet<NodePtr> = FxHashSet::default();
    let mut stack: Vec<(NodePtr, u32)> = roots
        .iter()
        .filter_map(|r| match r {
            Root::Node(p) => Some((*p, root_level)),
            _ => None,
        })
        .collect();
    while let Some((ptr, level)) = stack.pop() {
        seen.insert(ptr);
        uses.insert((ptr, level == 0));
        if level == 0 || !expanded.insert(ptr) {
            continue;
        }
        stack.extend(children(ptr).into_iter().map(|c| (c, level - 1)));
    }
    Reachable {
        items: count_per_table(seen),
        uses: count_per_table(uses.into_iter().map(|(p, _)| p)),
    }
}

/// How many of `ptrs` lie in each table.
fn count_per_table(ptrs: impl IntoIterator<Item = NodePtr>) -> Vec<u64> {
    let mut counts = vec![0; TABLE_COUNT as usize];
    for p in ptrs {
        counts[p.table()] += 1;
    }
    counts
}

fn node_children(node: &InnerNode) -> Vec<NodePtr> {
    node.children
        .iter()
        .filter_map(|c| match c {
            voxdag::edit::item::Child::Node(p) => Some(*p),
            _ => None,
        })
        .collect()
}

fn gpu_reachable(image: &HashDagImage, roots: &[Root]) -> Reachable {
    reachable_per_table(roots, image.root_level, |p| {
        node_children(&InnerNode::decode(&image.item(p).unwrap()).unwrap())
    })
}

fn cpu_reachable(editor: &CpuEditor) -> Reachable {
    let dag = editor.dag();
    reachable_per_table(editor.live_roots(), dag.root_level(), |p| {
        node_children(&dag.node(p).unwrap())
    })
}

/// Items stored per table (walking every bucket chain, which also checks the structure).
fn stored_per_table(image: &HashDagImage) -> Vec<u64> {
    image
        .tables
        .iter()
        .map(|t| t.walk().unwrap().items.len() as u64)
        .collect()
}

/// Deterministic noise, a solid slab and a ball.
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

/// Checks every live root of the GPU DAG against the CPU editor's, and the stored items against
/// the reachable ones.
fn check_after_gc(hd: &GpuHashDag, cpu: &CpuEditor, what: &str) {
    assert_eq!(
        hd.roots().len(),
        cpu.live_roots().len(),
        "{what}: live roots"
    );
    let image = hd.download().unwrap();
    for (i, (&g, &c)) in hd.roots().iter().zip(cpu.live_roots()).enumerate() {
        assert_eq!(
            image.voxels(g).unwrap(),
            cpu.dag().voxels(c).unwrap(),
            "{what}: voxels of live root {i}"
        );
    }
    let stored = stored_per_table(&image);
    let gpu = gpu_reachable(&image, hd.roots());
    let cpu_reach = cpu_reachable(cpu);
    assert_eq!(stored, gpu.items, "{what}: stored = reachable, per table");
    assert_eq!(
        gpu.uses, cpu_reach.uses,
        "{what}: GPU = CPU leaf and node uses, per table"
    );
    assert_eq!(
        cpu_reach.items.iter().sum::<u64>(),
        cpu.dag().item_count(),
        "{what}: the CPU editor keeps exactly its reachable items after its GC"
    );
}

/// Random edits with undo / redo and an undo depth, GC on the GPU and on the CPU reference
/// after every few steps; then undo through every kept root.
/// Returns the items the collections freed.
fn edits_undo_gc(
    ctx: &Arc<GpuContext>,
    variant: HashVariant,
    resolution: u32,
    steps: usize,
) -> u64 {
    let seed = 77 + variant.id() as u64 + resolution as u64;
    let dag = Svdag::from_voxels(&synthetic(resolution, seed)).unwrap();
    let depth = 3;
    let config = GpuHashDagConfig {
        auto_gc_threshold: None,
        ..GpuHashDagConfig::new(variant, 2048).with_undo_depth(depth)
    };
    let mut hd = GpuHashDag::load(ctx, &config, &dag, None).unwrap();
    let mut cpu_dag = HashDag::new(resolution, false).unwrap();
    let root = cpu_dag.insert_svdag(&dag, None).unwrap();
    let mut cpu = CpuEditor::new(cpu_dag, root, depth);
    let mut rng = common::Rng(seed);
    let mut freed = 0;
    for step in 0..steps {
        let what = format!("{variant:?} {resolution}^3 step {step}");
        match rng.below(6) {
            0 => assert_eq!(hd.undo(), cpu.undo(), "{what}: undo"),
            1 => assert_eq!(hd.redo(), cpu.redo(), "{what}: redo"),
            _ => {
                let tool = random_tool(&mut rng, resolution);
                gpu_edit(&mut hd, &tool).unwrap();
                cpu.edit(&tool).unwrap();
                assert!(hd.roots().len() <= depth + 1, "{what}: undo depth");
            }
        }
        if step % 3 == 2 {
            let stats = hd.gc(None).unwrap();
            let cpu_stats = cpu.gc().unwrap();
            assert_eq!(stats.live, cpu_stats.live, "{what}: live items");
            freed += stats.freed;
            check_after_gc(&hd, &cpu, &what);
            assert_eq!(
                stats.live_per_table,
                stored_per_table(&hd.download().unwrap()),
                "{what}: GC statistics"
            );
        }
    }
    // Undo through every kept root: each still reads back the CPU editor's voxels.
    while cpu.undo() {
        assert!(hd.undo());
        let image = hd.download().unwrap();
        assert_eq!(
            image.voxels(hd.root()).unwrap(),
            cpu.dag().voxels(cpu.root()).unwrap(),
            "{variant:?}: undo after GC"
        );
    }
    assert!(!hd.undo());
    // And forward again to the newest.
    while cpu.redo() {
        assert!(hd.redo());
        let image = hd.download().unwrap();
        assert_eq!(
            image.voxels(hd.root()).unwrap(),
            cpu.dag().voxels(cpu.root()).unwrap(),
            "{variant:?}: redo after GC"
        );
    }
    freed
}

#[test]
fn gc_keeps_every_live_root_and_frees_exactly_the_rest_for_every_variant() {
    let ctx = common::gpu();
    for variant in HashVariant::ALL {
        let freed = edits_undo_gc(&ctx, variant, 64, 15);
        assert!(freed > 0, "{variant:?}: the collections freed nothing");
    }
    edits_undo_gc(&ctx, HashVariant::AccelHash32, 128, 9);
    assert_clean(&ctx);
}

#[test]
fn gc_of_a_fresh_load_frees_nothing_and_an_empty_history_frees_everything() {
    let ctx = common::gpu();
    let dag = Svdag::from_voxels(&synthetic(32, 5)).unwrap();
    let config = GpuHashDagConfig::new(HashVariant::TicketBoard, 512).with_undo_depth(0);
    let mut hd = GpuHashDag::load(&ctx, &config, &dag, None).unwrap();
    let before = stored_per_table(&hd.download().unwrap());
    let mut profiler = Profiler::new(&ctx).unwrap();
    let stats = hd.gc(Some(&mut profiler)).unwrap();
    assert_eq!(stats.freed, 0);
    assert_eq!(stats.live_per_table, before);
    assert_eq!(stats.roots, 1);
    if profiler.is_available() {
        let names: Vec<&str> = profiler.passes().iter().map(|p| p.name.as_str()).collect();
        for pass in ["edit gc trace", "hash gc sweep"] {
            assert!(names.contains(&pass), "{pass} missing from {names:?}");
        }
    }
    // Undo depth 0: removing everything keeps one root, Empty, and GC frees every item.
    let all = Tool::Remove {
        shape: Shape::Cube,
        center: [16.0; 3],
        radius: 16.0,
    };
    gpu_edit(&mut hd, &all).unwrap();
    assert_eq!(hd.roots(), &[Root::Empty]);
    let stats = hd.gc(None).unwrap();
    assert_eq!(stats.live, 0);
    assert_eq!(stats.freed, before.iter().sum::<u64>());
    assert!(stats.slab_bytes_after <= stats.slab_bytes_before);
    assert_eq!(stored_per_table(&hd.download().unwrap()), vec![0; 9]);
    // The emptied tables take new edits.
    let ball = Tool::Add {
        shape: Shape::Sphere,
        center: [10.0, 11.0, 12.0],
        radius: 6.5,
        material: 0,
    };
    gpu_edit(&mut hd, &ball).unwrap();
    let mut cpu_dag = HashDag::new(32, false).unwrap();
    let root = cpu_dag.insert_svdag(&dag, None).unwrap();
    let mut cpu = CpuEditor::new(cpu_dag, root, 0);
    cpu.edit(&all).unwrap();
    cpu.edit(&ball).unwrap();
    hd.gc(None).unwrap();
    cpu.gc().unwrap();
    check_after_gc(&hd, &cpu, "after emptying");
    drop(profiler);
    drop(hd);
    assert_clean(&ctx);
}

/// A noise band 48 voxels thick in a 128^3 grid and 80 sphere removals inside it: in a pool of
/// one super block with one bucket per possible item (every item takes its own slab), the
/// sequence runs the pool out without GC.
fn tiny_pool_scene() -> (Svdag, Vec<Tool>) {
    let resolution = 128;
    let mut rng = common::Rng(11);
    let coords: Vec<[u32; 3]> = (0..resolution)
        .flat_map(|z| (0..resolution).flat_map(move |y| (0..48).map(move |x| [x, y, z])))
        .filter(|_| rng.below(2) == 0)
        .collect();
    let dag = Svdag::from_voxels(&Voxels::from_coords(resolution, coords)).unwrap();
    let tools: Vec<Tool> = (0..80)
        .map(|_| Tool::Remove {
            shape: Shape::Sphere,
            center: [
                rng.below(48) as f32 + 0.3,
                rng.below(128) as f32,
                rng.below(128) as f32,
            ],
            radius: 14.5,
        })
        .collect();
    (dag, tools)
}

/// The pool of [`tiny_pool_scene`]: one super block at most, a bucket per item.
fn tiny_pool(threshold: Option<f32>, undo_depth: usize) -> GpuHashDagConfig {
    GpuHashDagConfig {
        max_super_blocks: 1,
        auto_gc_threshold: threshold,
        ..GpuHashDagConfig::new(HashVariant::TicketBoard, 1 << 20).with_undo_depth(undo_depth)
    }
}

/// A long sequence of sphere removals in a tiny pool ([`tiny_pool_scene`]) runs out of slabs
/// without GC and runs to the end with automatic GC (and matches the CPU editor).
#[test]
fn auto_gc_lets_a_tiny_pool_run_a_long_edit_sequence() {
    let ctx = common::gpu();
    let (dag, tools) = tiny_pool_scene();
    let resolution = dag.resolution;
    let capped = |threshold| tiny_pool(threshold, 1);
    // Without GC the pool runs out.
    let mut hd = GpuHashDag::load(&ctx, &capped(None), &dag, None).unwrap();
    let failed = tools.iter().position(|t| match gpu_edit(&mut hd, t) {
        Ok(()) => false,
        Err(GpuDagError::Hash(HashError::Exhausted { .. })) => true,
        Err(e) => panic!("{e}"),
    });
    assert!(failed.is_some(), "the capped pool never ran out");
    eprintln!("without GC the pool ran out at edit {failed:?}");
    drop(hd);
    // With automatic GC the whole sequence runs.
    let mut hd = GpuHashDag::load(&ctx, &capped(Some(0.8)), &dag, None).unwrap();
    let mut cpu_dag = HashDag::new(resolution, false).unwrap();
    let root = cpu_dag.insert_svdag(&dag, None).unwrap();
    let mut cpu = CpuEditor::new(cpu_dag, root, 1);
    let mut runs = Vec::new();
    for (i, t) in tools.iter().enumerate() {
        let slabs = hd.pool_use().unwrap()[0].0;
        gpu_edit(&mut hd, t)
            .unwrap_or_else(|e| panic!("edit {i} ({slabs} leaf slabs before): {e}"));
        cpu.edit(t).unwrap();
        runs.extend(hd.take_auto_gc());
    }
    assert!(!runs.is_empty(), "no automatic GC ran");
    eprintln!("{} automatic collections", runs.len());
    assert!(runs.iter().all(|r| r.automatic && r.freed > 0));
    hd.gc(None).unwrap();
    cpu.gc().unwrap();
    check_after_gc(&hd, &cpu, "tiny pool");
    drop(hd);
    assert_clean(&ctx);
}

/// Automatic GC with a threshold no pool passes before an edit (1.0): every collection comes
/// from an edit that ran the tiny pool out ([`tiny_pool_scene`]); it frees the failed attempt's
/// items and the dropped history, and the edit's second attempt succeeds, so the whole
/// sequence runs and matches the CPU editor. With a history that keeps every root (nothing to
/// free but the failed attempt's items), an edit fails after its retry with `Exhausted`, and
/// the previous root stays current with its voxels.
#[test]
fn an_exhausted_edit_collects_garbage_and_retries() {
    let ctx = common::gpu();
    let (dag, tools) = tiny_pool_scene();
    let resolution = dag.resolution;
    let mut hd = GpuHashDag::load(&ctx, &tiny_pool(Some(1.0), 1), &dag, None).unwrap();
    let mut cpu_dag = HashDag::new(resolution, false).unwrap();
    let root = cpu_dag.insert_svdag(&dag, None).unwrap();
    let mut cpu = CpuEditor::new(cpu_dag, root, 1);
    let mut runs = Vec::new();
    for (i, t) in tools.iter().enumerate() {
        gpu_edit(&mut hd, t).unwrap_or_else(|e| panic!("edit {i}: {e}"));
        cpu.edit(t).unwrap();
        runs.extend(hd.take_auto_gc());
    }
    assert!(!runs.is_empty(), "no edit ran the pool out");
    eprintln!("{} collections after exhausted edits", runs.len());
    assert!(runs.iter().all(|r| r.automatic && r.freed > 0));
    hd.gc(None).unwrap();
    cpu.gc().unwrap();
    check_after_gc(&hd, &cpu, "retried edits");
    drop(hd);

    // Every root kept: the retry cannot find room, the edit fails and changes nothing.
    let mut hd = GpuHashDag::load(&ctx, &tiny_pool(Some(1.0), 1000), &dag, None).unwrap();
    let mut cpu_dag = HashDag::new(resolution, false).unwrap();
    let root = cpu_dag.insert_svdag(&dag, None).unwrap();
    let mut cpu = CpuEditor::new(cpu_dag, root, 1000);
    let mut failed = false;
    for (i, t) in tools.iter().enumerate() {
        let before = hd.root();
        match gpu_edit(&mut hd, t) {
            Ok(()) => {
                cpu.edit(t).unwrap();
            }
            Err(GpuDagError::Hash(HashError::Exhausted { .. })) => {
                assert_eq!(hd.root(), before, "edit {i}: root kept");
                assert!(
                    hd.take_auto_gc().iter().any(|r| r.automatic && r.freed > 0),
                    "edit {i}: the failed attempt's items were collected"
                );
                failed = true;
            }
            Err(e) => panic!("edit {i}: {e}"),
        }
        let image = hd.download().unwrap();
        assert_eq!(
            image.voxels(hd.root()).unwrap(),
            cpu.dag().voxels(cpu.root()).unwrap(),
            "edit {i}: voxels"
        );
        if failed {
            break;
        }
    }
    assert!(failed, "the pool never ran out with every root kept");
    drop(hd);
    assert_clean(&ctx);
}
