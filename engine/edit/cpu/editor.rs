//! The CPU reference editor: recursive edits over the hash DAG (rayon over the top subtrees)
//! and the undo history with GC.
//!
//! An edit walks the tree from the root: per child, the tool's coverage decides keep
//! (outside), fill / clear (inside, uniform result), or subdivide (partial); uniform cubes the
//! tool cannot change are kept without subdividing. Rebuilt nodes are find-or-inserted bottom
//! up on the way back, so equal subtrees are shared at once. New items are committed only when
//! the whole edit succeeded (all-or-nothing).

use rayon::prelude::*;

use super::{child_of, octant_offset, root_of, EditError, GcStats, HashDag, Inserter, RootSource};
use crate::edit::item::{Child, Leaf, Root};
use crate::edit::tool::{Coverage, Edit, Tool, Voxel};
use crate::scene::morton;

/// Nodes at least this many voxels wide edit their eight children in parallel.
const PARALLEL_SIZE: u32 = 256;

/// Edits `old` (a cube of side `4 << level` at `corner`) and returns its new content.
fn edit_child(
    ins: &Inserter,
    edit: &Edit,
    old: Child,
    level: u32,
    corner: Voxel,
) -> Result<Child, EditError> {
    let size = 4u32 << level;
    let uniform = match old {
        Child::Empty => Some(None),
        Child::Full(m) => Some(Some(m)),
        Child::Node(_) => None,
    };
    match edit.coverage(corner, size) {
        Coverage::Outside => return Ok(old),
        Coverage::Inside => match edit.tool {
            Tool::Add { material, .. } => return Ok(Child::Full(material)),
            Tool::Remove { .. } => return Ok(Child::Empty),
            Tool::Paint { material, .. } => return paint(ins, old, level, material),
            Tool::Fill { .. } | Tool::Copy(_) => {}
        },
        Coverage::Partial => {}
    }
    if let Some(state) = uniform {
        if edit.keeps_uniform(state) {
            return Ok(old);
        }
    }
    if level == 0 {
        let before = match old {
            Child::Empty => Leaf {
                mask: 0,
                materials: [0; 64],
            },
            Child::Full(m) => Leaf {
                mask: u64::MAX,
                materials: [m; 64],
            },
            Child::Node(ptr) => ins.dag.leaf(ptr)?,
        };
        let mut after = Leaf {
            mask: 0,
            materials: [0; 64],
        };
        for bit in 0..64 {
            let [x, y, z] = morton::decode(bit as u64);
            let v = [corner[0] + x, corner[1] + y, corner[2] + z];
            let was = (before.mask >> bit & 1 == 1).then_some(before.materials[bit]);
            if let Some(m) = edit.voxel(v, was) {
                after.mask |= 1 << bit;
                after.materials[bit] = m;
            }
        }
        return ins.leaf(&after);
    }
    let children = match old {
        Child::Empty => [Child::Empty; 8],
        Child::Full(m) => [Child::Full(m); 8],
        Child::Node(ptr) => ins.dag.node(ptr)?.children,
    };
    let half = size / 2;
    let edit_one = |o: usize| {
        edit_child(
            ins,
            edit,
            children[o],
            level - 1,
            octant_offset(corner, o, half),
        )
    };
    let new: Vec<Child> = if size >= PARALLEL_SIZE {
        (0..8)
            .into_par_iter()
            .map(edit_one)
            .collect::<Result<_, _>>()?
    } else {
        (0..8).map(edit_one).collect::<Result<_, _>>()?
    };
    ins.node(new.try_into().expect("eight children"))
}

/// `old` with every solid voxel set to `material` (geometry unchanged).
fn paint(ins: &Inserter, old: Child, level: u32, material: u8) -> Result<Child, EditError> {
    match old {
        Child::Empty => Ok(Child::Empty),
        Child::Full(_) => Ok(Child::Full(material)),
        Child::Node(ptr) if level == 0 => {
            let mut leaf = ins.dag.leaf(ptr)?;
            for bit in 0..64 {
                leaf.materials[bit] = if leaf.mask >> bit & 1 == 1 {
                    material
                } else {
                    0
                };
            }
            ins.leaf(&leaf)
        }
        Child::Node(ptr) => {
            let mut children = ins.dag.node(ptr)?.children;
            for c in &mut children {
                *c = paint(ins, *c, level - 1, material)?;
            }
            ins.node(children)
        }
    }
}

impl HashDag {
    /// Applies `tool` to the scene under `root` and returns the new root; `root` and every
    /// item reachable from it stay as they are. On error nothing is inserted.
    pub fn edit(&mut self, root: Root, tool: &Tool) -> Result<Root, EditError> {
        if !self.materials && matches!(tool, Tool::Paint { .. }) {
            // Geometry-only scenes have one material: painting changes nothing.
            tool.validate()?;
            return Ok(root);
        }
        let source = RootSource { dag: self, root };
        let edit = Edit::new(tool, &source, self.materials)?;
        let inserter = Inserter::new(self);
        let new = edit_child(&inserter, &edit, child_of(root), self.root_level(), [0; 3])?;
        let pending = inserter.into_pending();
        self.commit(pending);
        Ok(root_of(new))
    }
}

/// The CPU reference editor: a hash DAG, the current root and the undo / redo history.
#[derive(Clone, Debug)]
pub struct CpuEditor {
    dag: HashDag,
    /// Roots from the oldest kept undo step to the newest redo step.
    history: Vec<Root>,
    /// Index of the current root in `history`.
    current: usize,
    /// Most undo steps kept.
    undo_depth: usize,
}

impl CpuEditor {
    /// An editor over `dag` showing `root`, keeping at most `undo_depth` undo steps.
    pub fn new(dag: HashDag, root: Root, undo_depth: usize) -> CpuEditor {
        CpuEditor {
            dag,
            history: vec![root],
            current: 0,
            undo_depth,
        }
    }

    /// The hash DAG.
    pub fn dag(&self) -> &HashDag {
        &self.dag
    }

    /// The current root.
    pub fn root(&self) -> Root {
        self.history[self.current]
    }

    /// Every live root (undo steps, current, redo steps), oldest first.
    pub fn live_roots(&self) -> &[Root] {
        &self.history
    }

    /// Applies `tool`, makes the result current and drops the redo branch (and the oldest
    /// undo steps past the undo depth). On error the editor is unchanged.
    pub fn edit(&mut self, tool: &Tool) -> Result<Root, EditError> {
        let root = self.dag.edit(self.root(), tool)?;
        self.history.truncate(self.current + 1);
        self.history.push(root);
        self.current += 1;
        self.trim();
        Ok(root)
    }

    /// Steps back one edit; false when there is none.
    pub fn undo(&mut self) -> bool {
        let possible = self.current > 0;
        if possible {
            self.current -= 1;
        }
        possible
    }

    /// Steps forward one undone edit; false when there is none.
    pub fn redo(&mut self) -> bool {
        let possible = self.current + 1 < self.history.len();
        if possible {
            self.current += 1;
        }
        possible
    }

    /// Number of undo steps available.
    pub fn undo_steps(&self) -> usize {
        self.current
    }

    /// Number of redo steps available.
    pub fn redo_steps(&self) -> usize {
        self.history.len() - 1 - self.current
    }

    /// Sets the undo depth, dropping the oldest steps beyond it.
    pub fn set_undo_depth(&mut self, depth: usize) {
        self.undo_depth = depth;
        self.trim();
    }

    fn trim(&mut self) {
        let excess = self.current.saturating_sub(self.undo_depth);
        self.history.drain(..excess);
        self.current -= excess;
    }

    /// GC from every live root: frees every item no undo, current or redo root reaches.
    pub fn gc(&mut self) -> Result<GcStats, EditError> {
        self.dag.gc(&self.history)
    }

    /// Per-level unique stored items reachable from the current root (index 0 = leaves).
    pub fn unique_nodes_per_level(&self) -> Result<Vec<u64>, EditError> {
        self.dag.unique_nodes_per_level(self.root())
    }
}
