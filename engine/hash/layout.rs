//! Memory layout of the slab hash tables, shared word for word with `shaders/glsl/shared/hash_layout.h`.
//!
//! Everything is counted in 32-bit words. A table is: one `u32` head link per bucket, a pool of
//! super blocks (each its own buffer), a super-block address table and a status block. A *link*
//! is `slab + 1` (0 = none), so zeroed memory is an empty table and a free slab is all zeros.
//! See `docs/hash.md` for the picture.

/// Slots per slab.
pub const SLAB_SLOTS: u32 = 32;
/// Slabs per memory block (one 1024-bit occupancy bitmask per block).
pub const SLABS_PER_BLOCK: u32 = 1024;
/// Memory blocks per super block.
pub const BLOCKS_PER_SUPER_BLOCK: u32 = 16;
/// Slabs per super block (16 384).
pub const SLABS_PER_SUPER_BLOCK: u32 = SLABS_PER_BLOCK * BLOCKS_PER_SUPER_BLOCK;
/// Bitmask words of one block (1024 bits).
pub const BLOCK_BITMASK_WORDS: u32 = SLABS_PER_BLOCK / 32;
/// Words at the start of every super block holding its 16 block bitmasks (2 KiB).
pub const SUPER_BLOCK_BITMASK_WORDS: u32 = BLOCK_BITMASK_WORDS * BLOCKS_PER_SUPER_BLOCK;
/// Most super blocks one table may have; keeps every handle below [`HANDLE_INVALID`].
pub const MAX_SUPER_BLOCKS: u32 = 8191;
/// Largest item, in words.
pub const MAX_ITEM_WORDS: u32 = 10;

/// Handle value meaning "not found" (search) or "not inserted yet" (insert).
pub const HANDLE_MISS: u32 = 0xFFFF_FFFF;
/// Handle value of an item the layout cannot store (Atomic64: zero prefix).
pub const HANDLE_INVALID: u32 = 0xFFFF_FFFE;

/// Slab header word 0: link to the next slab of the bucket (`slab + 1`, 0 = end of chain).
pub const SLAB_NEXT: u32 = 0;
/// Slab header word 1: the per-slot "active" mask owned by garbage collection (zero here).
pub const SLAB_ACTIVE: u32 = 1;
/// Slab header word 2 (Ticket Board, Acceleration Hash): occupancy mask, bit s = slot s used.
pub const SLAB_OCCUPANCY: u32 = 2;
/// `HashPush::flags` bit: garbage collection may have cleared slots below occupied ones, so an
/// Atomic64 insert scans every slot of a slab instead of trusting that its items form a prefix.
pub const FLAG_HOLES: u32 = 1;
/// `HashPush::flags` bit: an insert round that first settles each missing item's
/// representative through the claim table (`engine/hash/claim.rs`); only the representatives
/// are inserted, the other copies get [`HANDLE_INVALID`].
pub const FLAG_CLAIMS: u32 = 2;

/// Words of the status block (see [`HashStatus`]).
pub const STATUS_WORDS: u32 = 5;

/// Seed of the primary hash (bucket choice).
pub const HASH_SEED: u32 = 0x9747_b28c;
/// Constant mixed into the primary hash to derive the secondary (acceleration) hash.
pub const SECONDARY_SALT: u32 = 0x85eb_ca6b;

/// Slab layout of a table, chosen at run time (one per table).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HashVariant {
    /// The first 8 bytes of the 32 slots stored contiguously and claimed with a 64-bit CAS
    /// (1-word items: a 32-bit CAS); an all-zero prefix marks an empty slot.
    Atomic64,
    /// A 32-bit occupancy mask per slab claimed with `atomicOr`; items contiguous.
    TicketBoard,
    /// Ticket Board plus a 32-bit secondary hash per slot, compared before the item.
    AccelHash32,
    /// Ticket Board plus an 8-bit secondary hash per slot, compared before the item.
    AccelHash8,
}

impl HashVariant {
    /// All variants, in the order of the dissertation's Table 4.2.
    pub const ALL: [HashVariant; 4] = [
        HashVariant::Atomic64,
        HashVariant::TicketBoard,
        HashVariant::AccelHash32,
        HashVariant::AccelHash8,
    ];

    /// Id passed to the shaders (specialization constant 2).
    pub fn id(self) -> u32 {
        match self {
            HashVariant::Atomic64 => 0,
            HashVariant::TicketBoard => 1,
            HashVariant::AccelHash32 => 2,
            HashVariant::AccelHash8 => 3,
        }
    }

    /// Short lowercase name (`atomic64`, `ticket_board`, `accel32`, `accel8`).
    pub fn name(self) -> &'static str {
        match self {
            HashVariant::Atomic64 => "atomic64",
            HashVariant::TicketBoard => "ticket_board",
            HashVariant::AccelHash32 => "accel32",
            HashVariant::AccelHash8 => "accel8",
        }
    }
}

/// A stable item handle: `slab << 5 | slot`, where `slab` is the global slab index
/// (`super_block * 16384 + block * 1024 + slab_in_block`). An item never moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Handle(pub u32);

impl Handle {
    /// The handle of `slot` in `slab`.
    pub fn new(slab: u32, slot: u32) -> Handle {
        Handle(slab << 5 | slot)
    }

    /// Global slab index.
    pub fn slab(self) -> u32 {
        self.0 >> 5
    }

    /// Slot inside the slab (0..32).
    pub fn slot(self) -> u32 {
        self.0 & 31
    }

    /// The handle from a raw GPU value, `None` for [`HANDLE_MISS`] and [`HANDLE_INVALID`].
    pub fn from_raw(raw: u32) -> Option<Handle> {
        (raw != HANDLE_MISS && raw != HANDLE_INVALID).then_some(Handle(raw))
    }
}

/// Word offsets inside one slab for a (variant, item size) pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlabLayout {
    /// The variant.
    pub variant: HashVariant,
    /// Words per item (1..=10).
    pub item_words: u32,
    /// Words per slab (always even, so 64-bit prefixes stay 8-byte aligned).
    pub slab_words: u32,
    /// First word of the per-slot secondary hashes (Acceleration Hash only).
    pub hashes: u32,
    /// First word of the item storage (see [`SlabLayout::item_word`]).
    pub items: u32,
}

impl SlabLayout {
    /// The layout, or `None` when `item_words` is outside 1..=10.
    pub fn new(variant: HashVariant, item_words: u32) -> Option<SlabLayout> {
        if !(1..=MAX_ITEM_WORDS).contains(&item_words) {
            return None;
        }
        let s = SLAB_SLOTS;
        let (hashes, items, end) = match variant {
            // [next, active] [32 prefixes of 2 words (1 word for 1-word items)] [32 x rest]
            HashVariant::Atomic64 if item_words == 1 => (0, 2, 2 + s),
            HashVariant::Atomic64 => (0, 2, 2 + 2 * s + s * (item_words - 2)),
            // [next, active, occupancy, reserved] [32 items]
            HashVariant::TicketBoard => (0, 4, 4 + s * item_words),
            // [next, active, occupancy, reserved] [32 hashes] [32 items]
            HashVariant::AccelHash32 => (4, 4 + s, 4 + s + s * item_words),
            // [next, active, occupancy, reserved] [32 hash bytes in 8 words] [32 items]
            HashVariant::AccelHash8 => (4, 4 + s / 4, 4 + s / 4 + s * item_words),
        };
        Some(SlabLayout {
            variant,
            item_words,
            slab_words: end.next_multiple_of(2),
            hashes,
            items,
        })
    }

    /// Word (inside the slab) holding word `w` of the item in `slot`.
    ///
    /// Atomic64 with 2+ words: words 0 and 1 are the slot's 64-bit prefix at `items + 2 * slot`,
    /// the rest at `items + 64 + slot * (item_words - 2) + (w - 2)`. Other layouts (and 1-word
    /// Atomic64): `items + slot * item_words + w`.
    pub fn item_word(&self, slot: u32, w: u32) -> u32 {
        if self.variant == HashVariant::Atomic64 && self.item_words >= 2 {
            if w < 2 {
                self.items + 2 * slot + w
            } else {
                self.items + 2 * SLAB_SLOTS + slot * (self.item_words - 2) + (w - 2)
            }
        } else {
            self.items + slot * self.item_words + w
        }
    }

    /// Bytes of one super block buffer: bitmasks, then 16 384 slabs.
    pub fn super_block_bytes(&self) -> u64 {
        4 * (SUPER_BLOCK_BITMASK_WORDS as u64
            + SLABS_PER_SUPER_BLOCK as u64 * self.slab_words as u64)
    }

    /// Whether this layout can store `item` (Atomic64 reserves the all-zero prefix for "empty").
    pub fn accepts(&self, item: &[u32]) -> bool {
        match self.variant {
            HashVariant::Atomic64 => item.iter().take(2).any(|&w| w != 0),
            _ => true,
        }
    }
}

/// murmur3's 32-bit finaliser.
pub fn fmix32(mut h: u32) -> u32 {
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^= h >> 16;
    h
}

/// Murmur3-style mix of every word of `words`, seeded with `seed ^ words.len()`, then `fmix32`.
pub fn murmur_words(seed: u32, words: &[u32]) -> u32 {
    let mut h = seed ^ words.len() as u32;
    for &w in words {
        let k = w
            .wrapping_mul(0xcc9e_2d51)
            .rotate_left(15)
            .wrapping_mul(0x1b87_3593);
        h = (h ^ k)
            .rotate_left(13)
            .wrapping_mul(5)
            .wrapping_add(0xe654_6b64);
    }
    fmix32(h)
}

/// Primary hash of an item (twin of `hash_item` in GLSL).
pub fn hash_item(item: &[u32]) -> u32 {
    murmur_words(HASH_SEED, item)
}

/// Bucket of an item with primary hash `hash`.
pub fn bucket_of(hash: u32, buckets: u32) -> u32 {
    hash % buckets
}

/// Secondary hash stored per slot by the Acceleration Hash (Accel8 keeps its low 8 bits).
pub fn secondary_hash(hash: u32) -> u32 {
    fmix32(hash ^ SECONDARY_SALT)
}

pub use super::gpu_shared::{HashPush, HashStatus};

const _: () = assert!(std::mem::size_of::<HashStatus>() == 4 * STATUS_WORDS as usize);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_are_even_and_disjoint() {
        for v in HashVariant::ALL {
            for w in 1..=MAX_ITEM_WORDS {
                let l = SlabLayout::new(v, w).unwrap();
                assert_eq!(l.slab_words % 2, 0);
                let mut used = vec![false; l.slab_words as usize];
                for slot in 0..SLAB_SLOTS {
                    for k in 0..w {
                        let i = l.item_word(slot, k) as usize;
                        assert!(i >= 2 && !used[i], "{v:?} w={w} slot={slot} k={k}");
                        used[i] = true;
                    }
                }
                if matches!(v, HashVariant::AccelHash32 | HashVariant::AccelHash8) {
                    assert!(l.hashes >= 4 && l.hashes < l.items);
                }
            }
        }
        assert!(SlabLayout::new(HashVariant::Atomic64, 0).is_none());
        assert!(SlabLayout::new(HashVariant::Atomic64, 11).is_none());
    }

    #[test]
    fn handles_stay_below_sentinels() {
        let last = Handle::new(MAX_SUPER_BLOCKS * SLABS_PER_SUPER_BLOCK - 1, 31);
        assert!(last.0 < HANDLE_INVALID);
        assert_eq!(Handle::from_raw(last.0), Some(last));
        assert_eq!(Handle::from_raw(HANDLE_MISS), None);
        assert_eq!(
            (last.slab(), last.slot()),
            (MAX_SUPER_BLOCKS * SLABS_PER_SUPER_BLOCK - 1, 31)
        );
    }

    #[test]
    fn hash_uses_every_word() {
        let a = [1u32, 2, 3, 4, 5, 6, 7, 8, 9, 10];
        for i in 0..a.len() {
            let mut b = a;
            b[i] ^= 1;
            assert_ne!(hash_item(&a), hash_item(&b));
        }
        assert_ne!(hash_item(&[0]), hash_item(&[0, 0]));
    }
}
