//! The CPU reference hash DAG (HashDAG-style): one hash table per item size (`item.rs`), with
//! find-or-insert, stable handles, import from an `Svdag`, voxel enumeration, conversion back
//! to an `Svdag`, per-level unique node counts and mark/sweep GC. `editor.rs` adds the edit
//! tools and the undo history on top.
//!
//! Handles are plain slot indices (`< 2^28`): freed slots go to a free list and are reused by
//! later inserts; a live item never moves, so its `NodePtr` stays valid until GC frees it.

mod editor;

use std::borrow::Cow;
use std::sync::Mutex;

use rustc_hash::FxHashMap;
use thiserror::Error;

pub use editor::CpuEditor;

pub use super::item::{child_of, root_of};
use super::item::{
    Child, InnerNode, ItemError, Leaf, NodePtr, Root, MAX_ITEM_WORDS, MIN_ITEM_WORDS,
    POINTER_HANDLE_BITS, TABLE_COUNT,
};
use super::tool::{ToolError, Voxel, VoxelSource};
use super::walk::{self, StoredDag};
use crate::dag::{DagError, Svdag, MAX_RESOLUTION};
use crate::scene::morton;

/// Most items one table may hold (handles must fit [`POINTER_HANDLE_BITS`]).
pub const MAX_TABLE_ITEMS: u32 = 1 << POINTER_HANDLE_BITS;

/// Errors of the CPU hash DAG and editor.
#[derive(Debug, Error)]
pub enum EditError {
    /// A table has no free handle left (the edit was not applied).
    #[error("hash DAG table of {words}-word items is full ({limit} items)")]
    TableFull {
        /// Item size of the full table.
        words: u32,
        /// Items the table may hold.
        limit: u32,
    },
    /// The grid side is not a power of two in `8..=2^21`.
    #[error("invalid resolution {0}")]
    Resolution(u32),
    /// Materials given for an import do not match the voxels.
    #[error("materials: {0}")]
    Materials(String),
    /// A tool's parameters are invalid.
    #[error(transparent)]
    Tool(#[from] ToolError),
    /// A stored item failed to decode (an internal invariant broke).
    #[error(transparent)]
    Item(#[from] ItemError),
    /// Conversion to an `Svdag` failed.
    #[error(transparent)]
    Dag(#[from] DagError),
}

/// One table: items of `words` words at `handle * words`.
#[derive(Clone, Debug)]
struct Table {
    words: usize,
    data: Vec<u32>,
    used: Vec<bool>,
    free: Vec<u32>,
    index: FxHashMap<Box<[u32]>, u32>,
}

impl Table {
    fn new(words: usize) -> Table {
        Table {
            words,
            data: Vec::new(),
            used: Vec::new(),
            free: Vec::new(),
            index: FxHashMap::default(),
        }
    }

    fn item(&self, handle: u32) -> &[u32] {
        let at = handle as usize * self.words;
        &self.data[at..at + self.words]
    }
}

/// What one GC pass did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GcStats {
    /// Items reachable from the live roots (kept).
    pub live: u64,
    /// Items freed.
    pub freed: u64,
}

/// The CPU hash DAG: every stored node and leaf of a scene and its history.
#[derive(Clone, Debug)]
pub struct HashDag {
    resolution: u32,
    materials: bool,
    tables: Vec<Table>,
    /// Most items per table (handles below it); `MAX_TABLE_ITEMS` unless lowered.
    item_limit: u32,
}

/// Items found missing during a parallel edit, inserted into the tables afterwards.
#[derive(Default)]
struct Pending {
    map: FxHashMap<Box<[u32]>, u32>,
    /// Free-list entries taken (from the end of the table's free list).
    reused: usize,
    /// Fresh handles taken past the end of the table.
    fresh: u32,
}

/// Find-or-insert against a read-only `HashDag`, usable from many threads: new items are
/// collected per table and committed by [`HashDag::commit`], so a failed edit leaves the
/// tables untouched.
pub(crate) struct Inserter<'a> {
    dag: &'a HashDag,
    pending: Vec<Mutex<Pending>>,
}

impl<'a> Inserter<'a> {
    fn new(dag: &'a HashDag) -> Inserter<'a> {
        Inserter {
            dag,
            pending: (0..TABLE_COUNT).map(|_| Mutex::default()).collect(),
        }
    }

    /// The pointer of an item equal to `words`, inserting it when new.
    fn insert(&self, words: &[u32]) -> Result<NodePtr, EditError> {
        let t = words.len() - MIN_ITEM_WORDS as usize;
        let table = &self.dag.tables[t];
        if let Some(&handle) = table.index.get(words) {
            return Ok(NodePtr::new(words.len() as u32, handle));
        }
        let mut pending = self.pending[t].lock().expect("no panics while locked");
        if let Some(&handle) = pending.map.get(words) {
            return Ok(NodePtr::new(words.len() as u32, handle));
        }
        let handle = if pending.reused < table.free.len() {
            pending.reused += 1;
            table.free[table.free.len() - pending.reused]
        } else {
            let handle = table.used.len() as u64 + pending.fresh as u64;
            let limit = self.dag.item_limit;
            if handle >= limit as u64 {
                return Err(EditError::TableFull {
                    words: words.len() as u32,
                    limit,
                });
            }
            pending.fresh += 1;
            handle as u32
        };
        pending.map.insert(words.into(), handle);
        Ok(NodePtr::new(words.len() as u32, handle))
    }

    /// The child for a node with these children (uniform nodes are not stored).
    fn node(&self, children: [Child; 8]) -> Result<Child, EditError> {
        let node = InnerNode { children };
        let mut words = Vec::with_capacity(9);
        match node.encode(&mut words) {
            None => Ok(node.uniform().expect("only uniform nodes have no item")),
            Some(()) => Ok(Child::Node(self.insert(&words)?)),
        }
    }

    /// The child for a leaf (empty and uniformly full leaves are not stored).
    fn leaf(&self, leaf: &Leaf) -> Result<Child, EditError> {
        let materials = self.dag.materials;
        if let Some(uniform) = leaf.as_uniform(materials) {
            return Ok(uniform);
        }
        let mut words = Vec::with_capacity(MAX_ITEM_WORDS as usize);
        leaf.encode(materials, &mut words);
        Ok(Child::Node(self.insert(&words)?))
    }

    fn into_pending(self) -> Vec<Pending> {
        self.pending
            .into_iter()
            .map(|p| p.into_inner().expect("no panics while locked"))
            .collect()
    }
}

impl StoredDag for HashDag {
    fn item_words(&self, ptr: NodePtr) -> Result<Cow<'_, [u32]>, ItemError> {
        let table = self
            .tables
            .get(ptr.table())
            .ok_or(ItemError::Missing(ptr.0))?;
        match table.used.get(ptr.handle() as usize) {
            Some(true) => Ok(Cow::Borrowed(table.item(ptr.handle()))),
            _ => Err(ItemError::Missing(ptr.0)),
        }
    }

    fn root_level(&self) -> u32 {
        HashDag::root_level(self)
    }

    fn has_materials(&self) -> bool {
        self.materials
    }
}

/// Voxel offset of octant `o` in a cube of side `2 * half`.
fn octant_offset(corner: Voxel, octant: usize, half: u32) -> Voxel {
    [
        corner[0] + (octant as u32 & 1) * half,
        corner[1] + (octant as u32 >> 1 & 1) * half,
        corner[2] + (octant as u32 >> 2) * half,
    ]
}

impl HashDag {
    /// An empty hash DAG for an `N^3` grid, with or without per-voxel materials.
    pub fn new(resolution: u32, materials: bool) -> Result<HashDag, EditError> {
        if !resolution.is_power_of_two() || !(8..=MAX_RESOLUTION).contains(&resolution) {
            return Err(EditError::Resolution(resolution));
        }
        Ok(HashDag {
            resolution,
            materials,
            tables: (MIN_ITEM_WORDS..=MAX_ITEM_WORDS)
                .map(|w| Table::new(w as usize))
                .collect(),
            item_limit: MAX_TABLE_ITEMS,
        })
    }

    /// Caps every table at `limit` items (at most `MAX_TABLE_ITEMS`), e.g. to bound memory;
    /// an edit that needs more fails with [`EditError::TableFull`] and changes nothing.
    pub fn set_item_limit(&mut self, limit: u32) {
        self.item_limit = limit.min(MAX_TABLE_ITEMS);
    }

    /// Grid side length.
    pub fn resolution(&self) -> u32 {
        self.resolution
    }

    /// Level of the root (`log2(N) - 2`; level 0 = 4^3 leaves).
    pub fn root_level(&self) -> u32 {
        self.resolution.trailing_zeros() - 2
    }

    /// True when leaves carry 4-bit materials.
    pub fn has_materials(&self) -> bool {
        self.materials
    }

    /// The stored words of an item.
    pub fn item(&self, ptr: NodePtr) -> &[u32] {
        self.tables[ptr.table()].item(ptr.handle())
    }

    /// Decodes the inner node at `ptr`.
    pub fn node(&self, ptr: NodePtr) -> Result<InnerNode, EditError> {
        Ok(InnerNode::decode(self.item(ptr))?)
    }

    /// Decodes the leaf at `ptr`.
    pub fn leaf(&self, ptr: NodePtr) -> Result<Leaf, EditError> {
        Ok(Leaf::decode(self.item(ptr), self.materials)?)
    }

    /// Find-or-insert of one item: the pointer of the stored equal item, or of a new one.
    pub fn find_or_insert(&mut self, words: &[u32]) -> Result<NodePtr, EditError> {
        if !(MIN_ITEM_WORDS as usize..=MAX_ITEM_WORDS as usize).contains(&words.len()) {
            return Err(ItemError::Size(words.len()).into());
        }
        let inserter = Inserter::new(self);
        let ptr = inserter.insert(words)?;
        let pending = inserter.into_pending();
        self.commit(pending);
        Ok(ptr)
    }

    /// Stores the items an `Inserter` collected.
    fn commit(&mut self, pending: Vec<Pending>) {
        for (table, pending) in self.tables.iter_mut().zip(pending) {
            let keep = table.free.len() - pending.reused;
            table.free.truncate(keep);
            let len = table.used.len() + pending.fresh as usize;
            table.used.resize(len, false);
            table.data.resize(len * table.words, 0);
            for (item, handle) in pending.map {
                let at = handle as usize * table.words;
                table.data[at..at + table.words].copy_from_slice(&item);
                table.used[handle as usize] = true;
                table.index.insert(item, handle);
            }
        }
    }

    /// True when `ptr` names a stored item (not freed by GC).
    pub fn is_stored(&self, ptr: NodePtr) -> bool {
        let table = &self.tables[ptr.table()];
        table
            .used
            .get(ptr.handle() as usize)
            .copied()
            .unwrap_or(false)
    }

    /// Number of stored items (all tables).
    pub fn item_count(&self) -> u64 {
        self.tables.iter().map(|t| t.index.len() as u64).sum()
    }

    /// Bytes of the stored items (words only, not the index).
    pub fn item_bytes(&self) -> u64 {
        self.tables
            .iter()
            .map(|t| (t.index.len() * t.words * 4) as u64)
            .sum()
    }

    /// Imports an `Svdag` (svdag32) bottom-up into canonical items; `materials` (one id per
    /// voxel in depth-first Morton order, as `Svdag::colors`) is required exactly when the
    /// hash DAG has materials. Returns the root.
    pub fn insert_svdag(
        &mut self,
        dag: &Svdag,
        materials: Option<&[u8]>,
    ) -> Result<Root, EditError> {
        if dag.resolution != self.resolution {
            return Err(EditError::Resolution(dag.resolution));
        }
        let inserter = Inserter::new(self);
        let root = match (self.materials, materials) {
            (false, None) => {
                let mut memo = vec![FxHashMap::default(); dag.root_level() as usize + 1];
                import_plain(&inserter, dag, 0, dag.root_level(), &mut memo)?
            }
            (true, Some(materials)) => {
                if let Some(bad) = materials.iter().find(|&&m| m >= 16) {
                    return Err(EditError::Materials(format!("material {bad} out of range")));
                }
                let mut next = 0usize;
                let root =
                    import_materials(&inserter, dag, 0, dag.root_level(), materials, &mut next)?;
                if next != materials.len() {
                    return Err(EditError::Materials(format!(
                        "{} materials for {next} voxels",
                        materials.len()
                    )));
                }
                root
            }
            (has, _) => {
                return Err(EditError::Materials(format!(
                    "the hash DAG {} materials",
                    if has { "needs" } else { "has no" }
                )))
            }
        };
        let pending = inserter.into_pending();
        self.commit(pending);
        Ok(root_of(root))
    }

    /// Material of voxel `v` under `root` (`None` when empty or outside the grid).
    pub fn voxel(&self, root: Root, v: Voxel) -> Option<u8> {
        if v.iter().any(|&c| c >= self.resolution) {
            return None;
        }
        let mut child = child_of(root);
        let mut level = self.root_level();
        loop {
            match child {
                Child::Empty => return None,
                Child::Full(m) => return Some(m),
                Child::Node(ptr) if level == 0 => {
                    let leaf = self.leaf(ptr).ok()?;
                    let bit = morton::encode(v[0] & 3, v[1] & 3, v[2] & 3) as usize;
                    return (leaf.mask >> bit & 1 == 1).then_some(leaf.materials[bit]);
                }
                Child::Node(ptr) => {
                    let bit = level + 1;
                    let octant =
                        (v[0] >> bit & 1) | (v[1] >> bit & 1) << 1 | (v[2] >> bit & 1) << 2;
                    child = self.node(ptr).ok()?.children[octant as usize];
                    level -= 1;
                }
            }
        }
    }

    /// `(Morton code, material)` of every solid voxel under `root`, ascending (materials 0
    /// without materials). Meant for tests and small scenes: full subtrees are expanded.
    pub fn voxels(&self, root: Root) -> Result<Vec<(u64, u8)>, EditError> {
        Ok(walk::voxels(self, root)?)
    }

    /// Converts the scene under `root` to a compact `Svdag` (geometry; no colours), with the
    /// same node order as `Svdag::from_voxels` of the same voxels.
    pub fn to_svdag(&self, root: Root) -> Result<Svdag, EditError> {
        walk::to_svdag(self, root)
    }

    /// Unique stored items reachable from `root`, per level (index 0 = leaves).
    pub fn unique_nodes_per_level(&self, root: Root) -> Result<Vec<u64>, EditError> {
        Ok(walk::unique_nodes_per_level(self, root)?)
    }

    /// Mark/sweep GC: keeps every item reachable from `roots`, frees the rest (their handles
    /// are reused by later inserts).
    pub fn gc(&mut self, roots: &[Root]) -> Result<GcStats, EditError> {
        // Bit 0: reached as a leaf, bit 1: reached as an inner node (an item may be both).
        let mut marks: Vec<Vec<u8>> = self.tables.iter().map(|t| vec![0; t.used.len()]).collect();
        let mut stack: Vec<(NodePtr, u32)> = roots
            .iter()
            .filter_map(|r| match r {
                Root::Node(p) => Some((*p, self.root_level())),
                _ => None,
            })
            .collect();
        while let Some((ptr, level)) = stack.pop() {
            let bit = if level == 0 { 1 } else { 2 };
            let mark = &mut marks[ptr.table()][ptr.handle() as usize];
            if *mark & bit != 0 {
                continue;
            }
            *mark |= bit;
            if level > 0 {
                for child in self.node(ptr)?.children {
                    if let Child::Node(p) = child {
                        stack.push((p, level - 1));
                    }
                }
            }
        }
        let mut stats = GcStats::default();
        for (table, marks) in self.tables.iter_mut().zip(marks) {
            for (handle, mark) in marks.into_iter().enumerate() {
                if !table.used[handle] {
                    continue;
                }
                if mark != 0 {
                    stats.live += 1;
                    continue;
                }
                let at = handle * table.words;
                let item: Box<[u32]> = table.data[at..at + table.words].into();
                table.index.remove(&item);
                table.data[at..at + table.words].fill(0);
                table.used[handle] = false;
                table.free.push(handle as u32);
                stats.freed += 1;
            }
        }
        Ok(stats)
    }
}

/// Imports the svdag node at word `node` (level `level`) without materials, memoized per node.
fn import_plain(
    ins: &Inserter,
    dag: &Svdag,
    node: usize,
    level: u32,
    memo: &mut [FxHashMap<usize, Child>],
) -> Result<Child, EditError> {
    if let Some(&c) = memo[level as usize].get(&node) {
        return Ok(c);
    }
    let child = if level == 0 {
        ins.leaf(&Leaf {
            mask: dag.leaf_mask(node),
            materials: [0; 64],
        })?
    } else {
        let mut children = [Child::Empty; 8];
        for (o, c) in children.iter_mut().enumerate() {
            if let Some(sub) = dag.child(node, o as u32) {
                *c = import_plain(ins, dag, sub, level - 1, memo)?;
            }
        }
        ins.node(children)?
    };
    memo[level as usize].insert(node, child);
    Ok(child)
}

/// Imports the svdag node at word `node` with per-voxel materials (`next`: index of the
/// node's first voxel in depth-first Morton order).
fn import_materials(
    ins: &Inserter,
    dag: &Svdag,
    node: usize,
    level: u32,
    materials: &[u8],
    next: &mut usize,
) -> Result<Child, EditError> {
    if level == 0 {
        let mask = dag.leaf_mask(node);
        let mut leaf = Leaf {
            mask,
            materials: [0; 64],
        };
        for bit in 0..64 {
            if mask >> bit & 1 == 1 {
                let m = *materials.get(*next).ok_or_else(|| {
                    EditError::Materials(format!("{} materials, more voxels", materials.len()))
                })?;
                leaf.materials[bit] = m;
                *next += 1;
            }
        }
        return ins.leaf(&leaf);
    }
    let mut children = [Child::Empty; 8];
    for (o, c) in children.iter_mut().enumerate() {
        if let Some(sub) = dag.child(node, o as u32) {
            *c = import_materials(ins, dag, sub, level - 1, materials, next)?;
        }
    }
    ins.node(children)
}

/// The scene under one root, as a [`VoxelSource`] for tools that read it.
pub struct RootSource<'a> {
    /// The hash DAG.
    pub dag: &'a HashDag,
    /// The root read.
    pub root: Root,
}

impl VoxelSource for RootSource<'_> {
    fn resolution(&self) -> u32 {
        self.dag.resolution
    }
    fn voxel(&self, v: Voxel) -> Option<u8> {
        self.dag.voxel(self.root, v)
    }
}
