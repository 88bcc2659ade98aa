//! Walks over a stored hash DAG, shared by the CPU reference hash DAG (`cpu::HashDag`) and the
//! host image of the GPU one (`gpu::HashDagImage`): voxel enumeration, unique nodes per level,
//! the materials in use and the conversion back to a compact `Svdag`.
//!
//! Everything but the voxel enumeration visits each stored node once, so its time and memory
//! follow the DAG, not the voxels: at 8192^3 one sphere of radius 1024 holds 4.5 G voxels
//! (72 GB as `(code, material)` pairs), a few thousand nodes.

use std::borrow::Cow;

use rustc_hash::{FxHashMap, FxHashSet};

use super::item::{child_of, Child, InnerNode, ItemError, Leaf, NodePtr, Root, MATERIAL_COUNT};
use crate::dag::build::LevelNodes;
use crate::dag::{DagError, Svdag};

/// A stored hash DAG as the walks read it: items by pointer.
pub trait StoredDag {
    /// The words of the item `ptr` names ([`ItemError::Missing`] when there is none).
    fn item_words(&self, ptr: NodePtr) -> Result<Cow<'_, [u32]>, ItemError>;
    /// Level of the root (`log2(N) - 2`; level 0 = 4^3 leaves).
    fn root_level(&self) -> u32;
    /// True when leaves carry 4-bit materials.
    fn has_materials(&self) -> bool;
}

fn node(dag: &impl StoredDag, ptr: NodePtr) -> Result<InnerNode, ItemError> {
    InnerNode::decode(&dag.item_words(ptr)?)
}

fn leaf(dag: &impl StoredDag, ptr: NodePtr) -> Result<Leaf, ItemError> {
    Leaf::decode(&dag.item_words(ptr)?, dag.has_materials())
}

/// Calls `visit(code, material)` for every solid voxel under `root`, in ascending Morton order
/// (materials 0 without materials). Memory: the recursion only.
pub fn for_each_voxel(
    dag: &impl StoredDag,
    root: Root,
    mut visit: impl FnMut(u64, u8),
) -> Result<(), ItemError> {
    visit_voxels(dag, child_of(root), dag.root_level(), 0, &mut visit)
}

fn visit_voxels(
    dag: &impl StoredDag,
    child: Child,
    level: u32,
    base: u64,
    visit: &mut impl FnMut(u64, u8),
) -> Result<(), ItemError> {
    // A level-l cube holds 64 * 8^l voxels, contiguous in Morton order from `base`.
    let span = 64u64 << (3 * level);
    match child {
        Child::Empty => {}
        Child::Full(m) => (base..base + span).for_each(|code| visit(code, m)),
        Child::Node(ptr) if level == 0 => {
            let leaf = leaf(dag, ptr)?;
            for v in 0..64u64 {
                if leaf.mask >> v & 1 == 1 {
                    visit(base + v, leaf.materials[v as usize]);
                }
            }
        }
        Child::Node(ptr) => {
            let node = node(dag, ptr)?;
            for (o, c) in node.children.iter().enumerate() {
                visit_voxels(dag, *c, level - 1, base + o as u64 * span / 8, visit)?;
            }
        }
    }
    Ok(())
}

/// `(Morton code, material)` of every solid voxel under `root`, ascending. 16 bytes per voxel:
/// meant for tests and small scenes ([`for_each_voxel`] streams them).
pub fn voxels(dag: &impl StoredDag, root: Root) -> Result<Vec<(u64, u8)>, ItemError> {
    let mut out = Vec::new();
    for_each_voxel(dag, root, |code, m| out.push((code, m)))?;
    Ok(out)
}

/// Unique stored items reachable from `root`, per level (index 0 = leaves; uniform children
/// are not items). Every item is decoded once, so a corrupt one is an error.
pub fn unique_nodes_per_level(dag: &impl StoredDag, root: Root) -> Result<Vec<u64>, ItemError> {
    let levels = dag.root_level() as usize + 1;
    let mut seen: Vec<FxHashSet<NodePtr>> = vec![FxHashSet::default(); levels];
    let mut stack = Vec::new();
    if let Root::Node(ptr) = root {
        stack.push((ptr, dag.root_level()));
    }
    while let Some((ptr, level)) = stack.pop() {
        if !seen[level as usize].insert(ptr) {
            continue;
        }
        if level == 0 {
            leaf(dag, ptr)?;
            continue;
        }
        for child in node(dag, ptr)?.children {
            if let Child::Node(p) = child {
                stack.push((p, level - 1));
            }
        }
    }
    Ok(seen.iter().map(|s| s.len() as u64).collect())
}

/// Solid voxels per material id.
pub type MaterialCounts = [u64; MATERIAL_COUNT as usize];

/// Solid voxels per material under `root`, one visit per unique item: `memo` keeps the counts
/// under each item (by pointer and level: an item may be a leaf and an inner node) and may be
/// shared between roots while no item is freed.
pub fn voxels_per_material(
    dag: &impl StoredDag,
    root: Root,
    memo: &mut FxHashMap<(NodePtr, u32), MaterialCounts>,
) -> Result<MaterialCounts, ItemError> {
    count_materials(dag, child_of(root), dag.root_level(), memo)
}

fn count_materials(
    dag: &impl StoredDag,
    child: Child,
    level: u32,
    memo: &mut FxHashMap<(NodePtr, u32), MaterialCounts>,
) -> Result<MaterialCounts, ItemError> {
    let mut counts = [0; MATERIAL_COUNT as usize];
    match child {
        Child::Empty => {}
        Child::Full(m) => {
            *counts
                .get_mut(m as usize)
                .ok_or(ItemError::Material(m as u32))? = 64u64 << (3 * level)
        }
        Child::Node(ptr) => {
            if let Some(n) = memo.get(&(ptr, level)) {
                return Ok(*n);
            }
            if level == 0 {
                let leaf = leaf(dag, ptr)?;
                for v in 0..64 {
                    if leaf.mask >> v & 1 == 1 {
                        counts[leaf.materials[v] as usize] += 1;
                    }
                }
            } else {
                for c in node(dag, ptr)?.children {
                    let below = count_materials(dag, c, level - 1, memo)?;
                    for (sum, n) in counts.iter_mut().zip(below) {
                        *sum += n;
                    }
                }
            }
            memo.insert((ptr, level), counts);
        }
    }
    Ok(counts)
}

/// Per-level node lists of an `Svdag` under construction (child ids, deduplicated).
#[derive(Default)]
struct SvdagLevel {
    nodes: LevelNodes,
    ids: FxHashMap<Vec<u32>, u32>,
}

impl SvdagLevel {
    fn push(&mut self, node: Vec<u32>) -> Result<u32, DagError> {
        if let Some(&id) = self.ids.get(&node) {
            return Ok(id);
        }
        let nodes = &mut self.nodes;
        let id = nodes.offsets.len() as u32;
        if nodes.words.len() + node.len() > u32::MAX as usize {
            return Err(DagError::TooLarge {
                words: (nodes.words.len() + node.len()) as u64,
            });
        }
        nodes.offsets.push(nodes.words.len() as u32);
        nodes.words.extend_from_slice(&node);
        self.ids.insert(node, id);
        Ok(id)
    }
}

/// The scene under `root` as a compact `Svdag` (geometry; no colours), converted node by node
/// with the same node order as `Svdag::from_voxels` of the same voxels.
pub fn to_svdag<E: From<ItemError> + From<DagError>>(
    dag: &impl StoredDag,
    root: Root,
) -> Result<Svdag, E> {
    let root_level = dag.root_level();
    let mut levels: Vec<SvdagLevel> = (0..=root_level).map(|_| SvdagLevel::default()).collect();
    let mut memo: FxHashMap<(Child, u32), u32> = FxHashMap::default();
    match child_of(root) {
        Child::Empty => {
            levels[root_level as usize].push(vec![0])?;
        }
        child => {
            convert::<E>(dag, child, root_level, &mut levels, &mut memo)?;
        }
    }
    let levels = levels.into_iter().map(|level| level.nodes).collect();
    Ok(Svdag::lay_out(4 << root_level, levels, Vec::new())?)
}

/// Id in `levels[level]` of the svdag node of a non-empty child.
fn convert<E: From<ItemError> + From<DagError>>(
    dag: &impl StoredDag,
    child: Child,
    level: u32,
    levels: &mut [SvdagLevel],
    memo: &mut FxHashMap<(Child, u32), u32>,
) -> Result<u32, E> {
    let key = match child {
        // Materials do not matter to geometry: one full node per level.
        Child::Full(_) => (Child::Full(0), level),
        c => (c, level),
    };
    if let Some(&id) = memo.get(&key) {
        return Ok(id);
    }
    let words = match child {
        Child::Empty => unreachable!("empty children are not converted"),
        Child::Full(_) if level == 0 => vec![u32::MAX, u32::MAX],
        Child::Node(ptr) if level == 0 => {
            let leaf = leaf(dag, ptr)?;
            vec![leaf.mask as u32, (leaf.mask >> 32) as u32]
        }
        Child::Full(_) => {
            let below = convert::<E>(dag, Child::Full(0), level - 1, levels, memo)?;
            let mut words = vec![0xff];
            words.extend([below; 8]);
            words
        }
        Child::Node(ptr) => {
            let node = node(dag, ptr)?;
            let mut words = vec![0];
            for (o, c) in node.children.iter().enumerate() {
                if *c != Child::Empty {
                    words[0] |= 1 << o;
                    let id = convert::<E>(dag, *c, level - 1, levels, memo)?;
                    words.push(id);
                }
            }
            words
        }
    };
    let id = levels[level as usize].push(words)?;
    memo.insert(key, id);
    Ok(id)
}
