//! Structural validation of an `Svdag`: after it passes, traversal cannot index out of bounds,
//! loop, or disagree with the colour array.

use super::{DagError, Svdag, MAX_RESOLUTION};

/// Where a structural problem was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Place {
    /// The resolution field.
    Resolution,
    /// Entry `l` of `level_starts`.
    Level(usize),
    /// Word `w` of `words`.
    Word(usize),
    /// The colour array.
    Colors,
}

/// A structural problem: where and what.
pub(crate) type Problem = (Place, String);

/// Marks word offsets (relative to a level's start) that begin a node.
struct NodeStarts {
    start: usize,
    bits: Vec<u64>,
}

impl NodeStarts {
    fn new(range: &std::ops::Range<usize>) -> Self {
        NodeStarts {
            start: range.start,
            bits: vec![0; (range.end - range.start).div_ceil(64)],
        }
    }
    fn set(&mut self, p: usize) {
        let i = p - self.start;
        self.bits[i / 64] |= 1 << (i % 64);
    }
    fn get(&self, p: usize) -> bool {
        match p.checked_sub(self.start) {
            Some(i) if i / 64 < self.bits.len() => self.bits[i / 64] >> (i % 64) & 1 == 1,
            _ => false,
        }
    }
}

impl Svdag {
    /// Checks every invariant of the layout in the module docs: level ranges, node sizes, masks,
    /// child pointers (each must point to the start of a node exactly one level down), non-empty
    /// leaves, a single root, and the colour count.
    pub fn validate(&self) -> Result<(), DagError> {
        self.check().map_err(|(place, reason)| DagError::Invalid {
            word: match place {
                Place::Word(w) => w as u64,
                _ => 0,
            },
            reason: match place {
                Place::Word(_) => reason,
                other => format!("{other:?}: {reason}"),
            },
        })
    }

    /// [`Svdag::validate`] with the place of the problem, for file errors.
    pub(crate) fn check(&self) -> Result<(), Problem> {
        let n = self.resolution;
        if !n.is_power_of_two() || !(8..=MAX_RESOLUTION).contains(&n) {
            return Err((
                Place::Resolution,
                format!("resolution {n} is not a power of two in 8..=2^21"),
            ));
        }
        let root_level = self.root_level() as usize;
        if self.level_starts.len() != root_level + 1 {
            return Err((
                Place::Level(0),
                format!(
                    "{} level starts for {} levels",
                    self.level_starts.len(),
                    root_level + 1
                ),
            ));
        }
        let len = self.words.len();
        if len == 0 || len > u32::MAX as usize {
            return Err((Place::Word(0), format!("{len} words")));
        }
        if self.level_starts[root_level] != 0 {
            return Err((
                Place::Level(root_level),
                "root level does not start at word 0".into(),
            ));
        }
        for l in 0..root_level {
            let (start, end) = (
                self.level_starts[l],
                if l == 0 {
                    len as u64
                } else {
                    self.level_starts[l - 1]
                },
            );
            if start > end || start < self.level_starts[l + 1] {
                return Err((Place::Level(l), format!("level start {start} out of order")));
            }
        }
        if self.words[0] == 0 {
            // Empty scene: a lone root word 0, all other levels empty, no colours.
            if len != 1 {
                return Err((Place::Word(1), "words after an empty root".into()));
            }
            if let Some(l) = (0..root_level).find(|&l| self.level_starts[l] != 1) {
                return Err((
                    Place::Level(l),
                    "non-empty level below an empty root".into(),
                ));
            }
            if !self.colors.is_empty() {
                return Err((Place::Colors, "colours for an empty scene".into()));
            }
            return Ok(());
        }
        // Leaves: pairs of words, never an empty mask.
        let leaves = self.level_range(0);
        if leaves.is_empty() || !(leaves.end - leaves.start).is_multiple_of(2) {
            return Err((
                Place::Level(0),
                format!("leaf level has {} words", leaves.end - leaves.start),
            ));
        }
        if let Some(p) = leaves.clone().step_by(2).find(|&p| self.leaf_mask(p) == 0) {
            return Err((Place::Word(p), "empty leaf".into()));
        }
        let mut below: Option<NodeStarts> = None; // None: level below is the leaf level
        for level in 1..=root_level as u32 {
            let range = self.level_range(level);
            if range.is_empty() {
                return Err((Place::Level(level as usize), "empty level".into()));
            }
            let child_range = self.level_range(level - 1);
            let mut starts = NodeStarts::new(&range);
            let mut nodes = 0usize;
            let mut p = range.start;
            while p < range.end {
                let mask = self.words[p];
                if mask == 0 || mask > 0xff {
                    return Err((Place::Word(p), format!("invalid child mask {mask:#x}")));
                }
                let end = p + 1 + mask.count_ones() as usize;
                if end > range.end {
                    return Err((Place::Word(p), "node runs past the end of its level".into()));
                }
                for q in p + 1..end {
                    let c = self.words[q] as usize;
                    let ok = match &below {
                        None => {
                            child_range.contains(&c) && (c - child_range.start).is_multiple_of(2)
                        }
                        Some(starts) => starts.get(c),
                    };
                    if !ok {
                        return Err((
                            Place::Word(q),
                            format!("child pointer {c} is not a node of level {}", level - 1),
                        ));
                    }
                }
                starts.set(p);
                nodes += 1;
                p = end;
            }
            if level as usize == root_level && nodes != 1 {
                return Err((
                    Place::Level(root_level),
                    format!("root level holds {nodes} nodes"),
                ));
            }
            below = Some(starts);
        }
        if !self.colors.is_empty() {
            let voxels = self.voxel_count();
            if self.colors.len() as u64 != voxels {
                return Err((
                    Place::Colors,
                    format!("{} colours for {voxels} voxels", self.colors.len()),
                ));
            }
        }
        Ok(())
    }
}
