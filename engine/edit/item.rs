//! The hash DAG's item format (dissertation §4.3.1): how inner nodes and leaves are stored as
//! 2..=10-word items in the per-size slab hash tables, and how child pointers name them.
//!
//! Shared by the CPU reference editor and the GPU editing passes (whose GLSL mirrors these
//! constants); `docs/hash-dag.md` explains the choices.
//!
//! - Levels are numbered as in `svdag32`: level 0 = 4^3 leaves, a level-`l` node covers
//!   `4 << l` voxels per side.
//! - **Inner node** = one header word + one word per present child, ascending octant order
//!   (`o = x | y << 1 | z << 2`). Header bits 0..8: child mask (child non-empty); bits 8..16:
//!   *full* mask (that child's whole cube is solid with one material; its word is the material id,
//!   not a pointer); bits 16..24: *temporary* mask (during an edit the child word indexes the
//!   temporary SVO; always zero in stored items); bits 24..32 reserved (zero).
//! - **Leaf** = the 64-bit occupancy mask of its 4^3 voxels (low word first, bit = Morton code of
//!   (x, y, z) in `0..4`, as in `svdag32`), then, in a scene with materials, one 4-bit material per
//!   occupied voxel in ascending Morton order, 8 per word (nibble `i` at bits `4 * (i % 8)` of word
//!   `i / 8`, unused nibbles zero). A leaf that is full with one material is never stored: its
//!   parent marks it full instead.
//! - Nodes and leaves of the same word count share one table: equal items are one entry whatever
//!   level reads them (the level is known from the traversal).
//! - **Pointer** (`NodePtr`, 32 bits) = `(words - 2) << 28 | handle`: the table (item size) and the
//!   slab-hash handle (`slab << 5 | slot`), so handles must stay below `2^28` (`MAX_TABLE_SLABS`).
//! - **Root** = empty, full with a material, or a pointer (`Root`).
//!
//! Every item starts with a non-zero word (a child mask or a leaf mask half), and every present
//! child's subtree is non-empty: the item of a canonical node is unique, so deduplication in the
//! tables is complete.

use thiserror::Error;

/// Fewest words of an item (a leaf mask, or a header with one child).
pub const MIN_ITEM_WORDS: u32 = 2;
/// Most words of an item (a leaf with 64 materials: 2 + 8).
pub const MAX_ITEM_WORDS: u32 = 10;
/// One table per item size `MIN_ITEM_WORDS..=MAX_ITEM_WORDS`.
pub const TABLE_COUNT: u32 = MAX_ITEM_WORDS - MIN_ITEM_WORDS + 1;
/// Bits of a pointer that hold the handle; the table index is above them.
pub const POINTER_HANDLE_BITS: u32 = 28;
/// Most slabs one table may have so that every handle fits in [`POINTER_HANDLE_BITS`].
pub const MAX_TABLE_SLABS: u32 = 1 << (POINTER_HANDLE_BITS - 5);
/// Number of materials (4-bit ids).
pub const MATERIAL_COUNT: u32 = 16;

/// Header bits 0..8: child present (non-empty).
pub const HEADER_CHILD_SHIFT: u32 = 0;
/// Header bits 8..16: child cube full with one material (child word = material id).
pub const HEADER_FULL_SHIFT: u32 = 8;
/// Header bits 16..24: child word indexes the temporary SVO (during an edit only).
pub const HEADER_TEMPORARY_SHIFT: u32 = 16;
/// Header bits that must be zero.
pub const HEADER_RESERVED_MASK: u32 = 0xff00_0000;

/// Why words are not a valid item.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum ItemError {
    /// Item sizes are `2..=10` words.
    #[error("item of {0} words (items have 2..=10)")]
    Size(usize),
    /// The word count does not match the header / mask.
    #[error("item of {got} words, its header or mask needs {expected}")]
    Length {
        /// Words given.
        got: usize,
        /// Words the header or mask implies.
        expected: usize,
    },
    /// Header with an empty child mask, reserved bits, a full or temporary bit on an absent
    /// child, or a temporary bit in a stored item.
    #[error("invalid inner node header {0:#010x}")]
    Header(u32),
    /// A full child's word is not a material id.
    #[error("material {0} out of range (0..16)")]
    Material(u32),
    /// Leaf with an empty mask, non-zero unused material nibbles, or full with one material.
    #[error("invalid leaf: {0}")]
    Leaf(&'static str),
    /// A pointer names no stored item.
    #[error("no item at pointer {0:#010x}")]
    Missing(u32),
}

/// A child pointer: the table (item size) and the handle in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodePtr(pub u32);

impl NodePtr {
    /// The pointer to `handle` (raw `slab << 5 | slot`) in the table of `words`-word items.
    pub fn new(words: u32, handle: u32) -> NodePtr {
        debug_assert!((MIN_ITEM_WORDS..=MAX_ITEM_WORDS).contains(&words));
        debug_assert!(handle < 1 << POINTER_HANDLE_BITS);
        NodePtr((words - MIN_ITEM_WORDS) << POINTER_HANDLE_BITS | handle)
    }

    /// Words of the item it points to (which table).
    pub fn words(self) -> u32 {
        (self.0 >> POINTER_HANDLE_BITS) + MIN_ITEM_WORDS
    }

    /// Index of its table (`words - 2`).
    pub fn table(self) -> usize {
        (self.0 >> POINTER_HANDLE_BITS) as usize
    }

    /// The raw slab-hash handle inside the table.
    pub fn handle(self) -> u32 {
        self.0 & ((1 << POINTER_HANDLE_BITS) - 1)
    }
}

/// The root of a hash DAG (one per history entry).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Root {
    /// No voxel.
    Empty,
    /// Every voxel solid with this material.
    Full(u8),
    /// An inner node at the root level.
    Node(NodePtr),
}

/// What one child slot of an inner node holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Child {
    /// Empty cube.
    Empty,
    /// Cube solid with one material.
    Full(u8),
    /// A stored node or leaf.
    Node(NodePtr),
}

/// The child slot equivalent of a root.
pub fn child_of(root: Root) -> Child {
    match root {
        Root::Empty => Child::Empty,
        Root::Full(m) => Child::Full(m),
        Root::Node(p) => Child::Node(p),
    }
}

/// The root for what a parent would store for the whole scene.
pub fn root_of(child: Child) -> Root {
    match child {
        Child::Empty => Root::Empty,
        Child::Full(m) => Root::Full(m),
        Child::Node(p) => Root::Node(p),
    }
}

/// A decoded inner node.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct InnerNode {
    /// Children by octant.
    pub children: [Child; 8],
}

impl InnerNode {
    /// Header word of the stored item (temporary mask zero).
    pub fn header(&self) -> u32 {
        let mut header = 0;
        for (octant, child) in self.children.iter().enumerate() {
            match child {
                Child::Empty => {}
                Child::Full(_) => {
                    header |=
                        (1 << octant) << HEADER_CHILD_SHIFT | (1 << octant) << HEADER_FULL_SHIFT
                }
                Child::Node(_) => header |= (1 << octant) << HEADER_CHILD_SHIFT,
            }
        }
        header
    }

    /// Appends the item's words to `out`; `None` when every child is empty or every child is full
    /// with one material (such a node is never stored: its parent holds `Empty` / `Full`).
    pub fn encode(&self, out: &mut Vec<u32>) -> Option<()> {
        match self.uniform() {
            Some(_) => return None,
            None if self.children.iter().all(|c| *c == Child::Empty) => return None,
            None => {}
        }
        out.push(self.header());
        for child in &self.children {
            match *child {
                Child::Empty => {}
                Child::Full(material) => out.push(material as u32),
                Child::Node(ptr) => out.push(ptr.0),
            }
        }
        Some(())
    }

    /// `Some(Child::Empty | Child::Full(m))` when all eight children are that same value.
    pub fn uniform(&self) -> Option<Child> {
        let first = self.children[0];
        let uniform = matches!(first, Child::Empty | Child::Full(_))
            && self.children.iter().all(|c| *c == first);
        uniform.then_some(first)
    }

    /// Decodes a stored inner-node item (temporary bits rejected).
    pub fn decode(words: &[u32]) -> Result<InnerNode, ItemError> {
        check_size(words.len())?;
        let header = words[0];
        let mask = (header >> HEADER_CHILD_SHIFT) & 0xff;
        let full = (header >> HEADER_FULL_SHIFT) & 0xff;
        let temporary = (header >> HEADER_TEMPORARY_SHIFT) & 0xff;
        if mask == 0 || header & HEADER_RESERVED_MASK != 0 || full & !mask != 0 || temporary != 0 {
            return Err(ItemError::Header(header));
        }
        let expected = 1 + mask.count_ones() as usize;
        if words.len() != expected {
            return Err(ItemError::Length {
                got: words.len(),
                expected,
            });
        }
        let mut children = [Child::Empty; 8];
        let mut next = 1;
        for (octant, child) in children.iter_mut().enumerate() {
            if mask >> octant & 1 == 0 {
                continue;
            }
            let word = words[next];
            next += 1;
            *child = if full >> octant & 1 == 1 {
                if word >= MATERIAL_COUNT {
                    return Err(ItemError::Material(word));
                }
                Child::Full(word as u8)
            } else {
                let ptr = NodePtr(word);
                if ptr.words() > MAX_ITEM_WORDS {
                    return Err(ItemError::Header(header));
                }
                Child::Node(ptr)
            };
        }
        let node = InnerNode { children };
        if node.uniform().is_some() {
            return Err(ItemError::Header(header));
        }
        Ok(node)
    }
}

/// A decoded leaf: occupancy of its 4^3 voxels and, in scenes with materials, one material each.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Leaf {
    /// Bit `morton(x, y, z)` set when the voxel is solid.
    pub mask: u64,
    /// Material per voxel, indexed by Morton code (only occupied entries matter; zero elsewhere).
    pub materials: [u8; 64],
}

impl Leaf {
    /// Words of the item for `mask` (`with_materials`: one nibble per occupied voxel).
    pub fn item_words(mask: u64, with_materials: bool) -> u32 {
        let materials = if with_materials {
            mask.count_ones().div_ceil(8)
        } else {
            0
        };
        MIN_ITEM_WORDS + materials
    }

    /// What the parent stores for this leaf: `Empty`, `Full(m)` for a full leaf of one material
    /// (`m = 0` without materials), or `None` when the leaf must be stored as an item.
    pub fn as_uniform(&self, with_materials: bool) -> Option<Child> {
        if self.mask == 0 {
            return Some(Child::Empty);
        }
        if self.mask != u64::MAX {
            return None;
        }
        if !with_materials {
            return Some(Child::Full(0));
        }
        let first = self.materials[0];
        self.materials
            .iter()
            .all(|m| *m == first)
            .then_some(Child::Full(first))
    }

    /// Appends the item's words to `out`; `None` when the leaf is empty or uniformly full.
    pub fn encode(&self, with_materials: bool, out: &mut Vec<u32>) -> Option<()> {
        if self.as_uniform(with_materials).is_some() {
            return None;
        }
        out.push(self.mask as u32);
        out.push((self.mask >> 32) as u32);
        if with_materials {
            let start = out.len();
            out.resize(start + self.mask.count_ones().div_ceil(8) as usize, 0);
            for (rank, voxel) in set_bits(self.mask).enumerate() {
                out[start + rank / 8] |= (self.materials[voxel] as u32 & 0xf) << (4 * (rank % 8));
            }
        }
        Some(())
    }

    /// Decodes a stored leaf item.
    pub fn decode(words: &[u32], with_materials: bool) -> Result<Leaf, ItemError> {
        check_size(words.len())?;
        let mask = words[0] as u64 | (words[1] as u64) << 32;
        if mask == 0 {
            return Err(ItemError::Leaf("empty mask"));
        }
        let expected = Leaf::item_words(mask, with_materials) as usize;
        if words.len() != expected {
            return Err(ItemError::Length {
                got: words.len(),
                expected,
            });
        }
        let mut leaf = Leaf {
            mask,
            materials: [0; 64],
        };
        if with_materials {
            let count = mask.count_ones() as usize;
            for (rank, voxel) in set_bits(mask).enumerate() {
                leaf.materials[voxel] = (words[2 + rank / 8] >> (4 * (rank % 8)) & 0xf) as u8;
            }
            let last = words[words.len() - 1];
            if !count.is_multiple_of(8) && last >> (4 * (count % 8)) != 0 {
                return Err(ItemError::Leaf("non-zero unused material nibbles"));
            }
        }
        if leaf.as_uniform(with_materials).is_some() {
            return Err(ItemError::Leaf(
                "full with one material (stored in the parent)",
            ));
        }
        Ok(leaf)
    }
}

fn check_size(words: usize) -> Result<(), ItemError> {
    if (MIN_ITEM_WORDS as usize..=MAX_ITEM_WORDS as usize).contains(&words) {
        Ok(())
    } else {
        Err(ItemError::Size(words))
    }
}

/// Indices of the set bits of `mask`, ascending.
fn set_bits(mask: u64) -> impl Iterator<Item = usize> {
    (0..64).filter(move |bit| mask >> bit & 1 == 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pointer_round_trips_table_and_handle() {
        for words in MIN_ITEM_WORDS..=MAX_ITEM_WORDS {
            let ptr = NodePtr::new(words, (MAX_TABLE_SLABS - 1) << 5 | 31);
            assert_eq!(ptr.words(), words);
            assert_eq!(ptr.table(), (words - 2) as usize);
            assert_eq!(ptr.handle(), (MAX_TABLE_SLABS - 1) << 5 | 31);
        }
    }

    #[test]
    fn inner_node_round_trips_and_rejects_uniform_nodes() {
        let mut children = [Child::Empty; 8];
        children[1] = Child::Full(7);
        children[6] = Child::Node(NodePtr::new(3, 12345));
        let node = InnerNode { children };
        let mut words = Vec::new();
        node.encode(&mut words).unwrap();
        assert_eq!(
            words,
            vec![0b0100_0010 | 0b10 << 8, 7, NodePtr::new(3, 12345).0]
        );
        assert_eq!(InnerNode::decode(&words).unwrap(), node);

        let full = InnerNode {
            children: [Child::Full(3); 8],
        };
        assert_eq!(full.encode(&mut Vec::new()), None);
        let empty = InnerNode {
            children: [Child::Empty; 8],
        };
        assert_eq!(empty.encode(&mut Vec::new()), None);
        let mut stored = vec![0xffff];
        stored.extend([3; 8]);
        assert!(InnerNode::decode(&stored).is_err());
        assert!(
            InnerNode::decode(&[1 | 1 << 16, 5]).is_err(),
            "temporary bit in a stored item"
        );
        assert!(
            InnerNode::decode(&[1 | 1 << 8, 16]).is_err(),
            "material out of range"
        );
        assert!(
            InnerNode::decode(&[3, 5]).is_err(),
            "two children, one word"
        );
    }

    #[test]
    fn leaf_round_trips_with_and_without_materials() {
        let mut leaf = Leaf {
            mask: 0x8000_0000_0000_0301,
            materials: [0; 64],
        };
        leaf.materials[0] = 1;
        leaf.materials[8] = 15;
        leaf.materials[9] = 2;
        leaf.materials[63] = 9;
        let mut words = Vec::new();
        leaf.encode(true, &mut words).unwrap();
        assert_eq!(
            words,
            vec![0x301, 0x8000_0000, 1 | 15 << 4 | 2 << 8 | 9 << 12]
        );
        assert_eq!(Leaf::decode(&words, true).unwrap(), leaf);

        let geometry = Leaf {
            mask: leaf.mask,
            materials: [0; 64],
        };
        let mut plain = Vec::new();
        geometry.encode(false, &mut plain).unwrap();
        assert_eq!(plain, vec![0x301, 0x8000_0000]);
        assert_eq!(Leaf::decode(&plain, false).unwrap(), geometry);

        let full = Leaf {
            mask: u64::MAX,
            materials: [4; 64],
        };
        assert_eq!(full.as_uniform(true), Some(Child::Full(4)));
        assert_eq!(full.encode(true, &mut Vec::new()), None);
        let mut mixed = full;
        mixed.materials[17] = 5;
        let mut words = Vec::new();
        mixed.encode(true, &mut words).unwrap();
        assert_eq!(words.len(), 10);
        assert_eq!(Leaf::decode(&words, true).unwrap(), mixed);
        assert!(
            Leaf::decode(&[0x301, 0x8000_0000, 1 << 16 | 1], true).is_err(),
            "unused nibble set"
        );
    }
}
