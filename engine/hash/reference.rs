//! The CPU reference: the same slab layouts, allocator bitmasks and handles as the GPU tables,
//! on a host memory image ([`TableImage`]), operated sequentially and deterministically.
//!
//! [`TableImage`] is also what [`super::GpuHashTable::download`] returns, so one structural walk
//! ([`TableImage::walk`]) checks GPU and CPU tables alike. Handles differ between the two (GPU
//! allocation order is racy): compare item sets and hit/miss answers, not handles.

use std::collections::HashSet;

use super::layout::{
    bucket_of, hash_item, secondary_hash, Handle, HashStatus, HashVariant, SlabLayout,
    SLABS_PER_SUPER_BLOCK, SLAB_NEXT, SLAB_OCCUPANCY, SLAB_SLOTS, SUPER_BLOCK_BITMASK_WORDS,
};
use super::HashError;

/// A table's memory as words: bucket heads, super blocks (bitmasks then slabs), status block.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TableImage {
    /// The slab layout.
    pub layout: SlabLayout,
    /// One link (`slab + 1`, 0 = empty) per bucket.
    pub heads: Vec<u32>,
    /// Every super block: 512 bitmask words, then 16 384 slabs of `layout.slab_words`.
    pub super_blocks: Vec<Vec<u32>>,
    /// The status block.
    pub status: HashStatus,
}

/// What [`TableImage::walk`] found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WalkReport {
    /// Every stored item with its handle, in walk order.
    pub items: Vec<(Handle, Vec<u32>)>,
    /// Slabs linked into chains.
    pub slabs: u64,
    /// Longest chain, in slabs.
    pub max_chain: u32,
}

impl TableImage {
    /// An empty image with `buckets` buckets and `super_blocks` zeroed super blocks.
    pub fn new(layout: SlabLayout, buckets: u32, super_blocks: u32) -> TableImage {
        let mut image = TableImage {
            layout,
            heads: vec![0; buckets as usize],
            super_blocks: Vec::new(),
            status: HashStatus::default(),
        };
        image.grow(super_blocks);
        image
    }

    /// Adds `count` zeroed super blocks.
    pub fn grow(&mut self, count: u32) {
        let words = (self.layout.super_block_bytes() / 4) as usize;
        for _ in 0..count {
            self.super_blocks.push(vec![0; words]);
        }
    }

    /// Slabs the pool can hold.
    pub fn capacity_slabs(&self) -> u64 {
        self.super_blocks.len() as u64 * SLABS_PER_SUPER_BLOCK as u64
    }

    fn slab_range(&self, slab: u32) -> (usize, std::ops::Range<usize>) {
        let sb = (slab / SLABS_PER_SUPER_BLOCK) as usize;
        let local = (slab % SLABS_PER_SUPER_BLOCK) as usize;
        let w = self.layout.slab_words as usize;
        let start = SUPER_BLOCK_BITMASK_WORDS as usize + local * w;
        (sb, start..start + w)
    }

    /// The words of a slab (`None` beyond the pool).
    pub fn slab(&self, slab: u32) -> Option<&[u32]> {
        let (sb, range) = self.slab_range(slab);
        self.super_blocks.get(sb).map(|b| &b[range])
    }

    fn slab_mut(&mut self, slab: u32) -> &mut [u32] {
        let (sb, range) = self.slab_range(slab);
        &mut self.super_blocks[sb][range]
    }

    /// Whether the allocator bitmask marks `slab` as allocated.
    pub fn is_allocated(&self, slab: u32) -> bool {
        let sb = (slab / SLABS_PER_SUPER_BLOCK) as usize;
        let local = slab % SLABS_PER_SUPER_BLOCK;
        self.super_blocks
            .get(sb)
            .is_some_and(|b| b[(local / 32) as usize] >> (local % 32) & 1 == 1)
    }

    /// Slabs marked allocated in the bitmasks.
    pub fn allocated_slabs(&self) -> u64 {
        self.super_blocks
            .iter()
            .map(|b| {
                b[..SUPER_BLOCK_BITMASK_WORDS as usize]
                    .iter()
                    .map(|m| m.count_ones() as u64)
                    .sum::<u64>()
            })
            .sum()
    }

    /// Whether `slot` of a slab's words is occupied, by the layout's own marker.
    pub fn slot_occupied(&self, words: &[u32], slot: u32) -> bool {
        let l = &self.layout;
        match l.variant {
            HashVariant::Atomic64 if l.item_words == 1 => words[l.item_word(slot, 0) as usize] != 0,
            HashVariant::Atomic64 => {
                words[l.item_word(slot, 0) as usize] | words[l.item_word(slot, 1) as usize] != 0
            }
            _ => words[SLAB_OCCUPANCY as usize] >> slot & 1 == 1,
        }
    }

    /// The item in `slot` of a slab's words.
    pub fn slot_item(&self, words: &[u32], slot: u32) -> Vec<u32> {
        (0..self.layout.item_words)
            .map(|w| words[self.layout.item_word(slot, w) as usize])
            .collect()
    }

    /// The secondary hash stored for `slot` (Acceleration Hash; 0 for other layouts).
    pub fn slot_secondary(&self, words: &[u32], slot: u32) -> u32 {
        let h = self.layout.hashes as usize;
        match self.layout.variant {
            HashVariant::AccelHash32 => words[h + slot as usize],
            HashVariant::AccelHash8 => words[h + slot as usize / 4] >> (8 * (slot % 4)) & 0xff,
            _ => 0,
        }
    }

    /// The secondary hash as this layout stores it.
    pub fn stored_secondary(&self, hash: u32) -> u32 {
        match self.layout.variant {
            HashVariant::AccelHash8 => secondary_hash(hash) & 0xff,
            _ => secondary_hash(hash),
        }
    }

    /// The item named by a handle, `None` when the handle names no occupied slot.
    pub fn read(&self, handle: Handle) -> Option<Vec<u32>> {
        let words = self.slab(handle.slab())?;
        self.slot_occupied(words, handle.slot())
            .then(|| self.slot_item(words, handle.slot()))
    }

    /// Walks every bucket and checks the structure: each chain's slabs are allocated, inside
    /// the pool and in no other chain; every occupied slot holds an item of this bucket (and
    /// its secondary hash); free slots and unused header words are zero; the bitmasks mark
    /// exactly the linked slabs and agree with the status block's slab count.
    pub fn walk(&self) -> Result<WalkReport, String> {
        let l = self.layout;
        let buckets = self.heads.len() as u32;
        let mut seen = HashSet::new();
        let mut report = WalkReport::default();
        for (bucket, &head) in self.heads.iter().enumerate() {
            let mut link = head;
            let mut chain = 0;
            while link != 0 {
                let slab = link - 1;
                let words = self
                    .slab(slab)
                    .ok_or(format!("bucket {bucket}: slab {slab} is beyond the pool"))?;
                if !seen.insert(slab) {
                    return Err(format!("bucket {bucket}: slab {slab} is linked twice"));
                }
                if !self.is_allocated(slab) {
                    return Err(format!(
                        "bucket {bucket}: slab {slab} is not marked allocated"
                    ));
                }
                if l.variant != HashVariant::Atomic64 && words[3] != 0 {
                    return Err(format!("slab {slab}: reserved header word is {}", words[3]));
                }
                for slot in 0..SLAB_SLOTS {
                    let item = self.slot_item(words, slot);
                    if !self.slot_occupied(words, slot) {
                        if item.iter().any(|&w| w != 0) || self.slot_secondary(words, slot) != 0 {
                            return Err(format!("slab {slab} slot {slot}: free but not zero"));
                        }
                        continue;
                    }
                    let h = hash_item(&item);
                    if bucket_of(h, buckets) != bucket as u32 {
                        return Err(format!(
                            "slab {slab} slot {slot}: item {item:?} belongs to bucket {}, found in {bucket}",
                            bucket_of(h, buckets)
                        ));
                    }
                    let is_accel = matches!(
                        l.variant,
                        HashVariant::AccelHash32 | HashVariant::AccelHash8
                    );
                    if is_accel && self.slot_secondary(words, slot) != self.stored_secondary(h) {
                        return Err(format!("slab {slab} slot {slot}: wrong secondary hash"));
                    }
                    report.items.push((Handle::new(slab, slot), item));
                }
                chain += 1;
                link = words[SLAB_NEXT as usize];
            }
            report.max_chain = report.max_chain.max(chain);
        }
        report.slabs = seen.len() as u64;
        let allocated = self.allocated_slabs();
        if allocated != report.slabs {
            return Err(format!(
                "{allocated} slabs are marked allocated but {} are linked",
                report.slabs
            ));
        }
        if self.status.allocated_slabs as u64 != allocated {
            return Err(format!(
                "status counts {} allocated slabs, bitmasks {allocated}",
                self.status.allocated_slabs
            ));
        }
        Ok(report)
    }
}

/// The sequential CPU reference table.
#[derive(Clone, Debug)]
pub struct ReferenceTable {
    image: TableImage,
}

impl ReferenceTable {
    /// An empty table (one super block); errors for item sizes outside 1..=10 or zero buckets.
    pub fn new(
        variant: HashVariant,
        item_words: u32,
        buckets: u32,
    ) -> Result<ReferenceTable, HashError> {
        let layout = SlabLayout::new(variant, item_words).ok_or_else(|| {
            HashError::Config(format!("item size {item_words} is outside 1..=10"))
        })?;
        if buckets == 0 {
            return Err(HashError::Config(
                "a table needs at least one bucket".into(),
            ));
        }
        Ok(ReferenceTable {
            image: TableImage::new(layout, buckets, 1),
        })
    }

    /// The memory image.
    pub fn image(&self) -> &TableImage {
        &self.image
    }

    fn check(&self, item: &[u32], index: usize) -> Result<(), HashError> {
        let l = self.image.layout;
        if item.len() != l.item_words as usize {
            return Err(HashError::InvalidArgument(format!(
                "item {index} has {} words, the table {}",
                item.len(),
                l.item_words
            )));
        }
        if !l.accepts(item) {
            return Err(HashError::InvalidItem {
                index,
                variant: l.variant.name(),
                reason: "the first two words (the only word of a 1-word item) are zero, which marks an empty slot",
            });
        }
        Ok(())
    }

    fn bucket(&self, hash: u32) -> usize {
        bucket_of(hash, self.image.heads.len() as u32) as usize
    }

    /// The handle of `item`, or `None`.
    pub fn search(&self, item: &[u32]) -> Option<Handle> {
        if item.len() != self.image.layout.item_words as usize || !self.image.layout.accepts(item) {
            return None;
        }
        let mut link = self.image.heads[self.bucket(hash_item(item))];
        while link != 0 {
            let words = self.image.slab(link - 1)?;
            let found = (0..SLAB_SLOTS).find(|&s| {
                self.image.slot_occupied(words, s) && self.image.slot_item(words, s) == item
            });
            if let Some(slot) = found {
                return Some(Handle::new(link - 1, slot));
            }
            link = words[SLAB_NEXT as usize];
        }
        None
    }

    /// Inserts an item assumed absent (the GPU insert rule: first free slot of the first slab
    /// with one, else a new slab at the chain's end).
    pub fn insert(&mut self, item: &[u32]) -> Result<Handle, HashError> {
        self.check(item, 0)?;
        let l = self.image.layout;
        let hash = hash_item(item);
        let bucket = self.bucket(hash);
        let mut prev: Option<u32> = None;
        let mut link = self.image.heads[bucket];
        loop {
            if link == 0 {
                let slab = self.alloc_slab();
                match prev {
                    None => self.image.heads[bucket] = slab + 1,
                    Some(p) => self.image.slab_mut(p)[SLAB_NEXT as usize] = slab + 1,
                }
                link = slab + 1;
            }
            let slab = link - 1;
            let free = {
                let words = self.image.slab(slab).expect("linked slab inside the pool");
                (0..SLAB_SLOTS).find(|&s| !self.image.slot_occupied(words, s))
            };
            if let Some(slot) = free {
                let secondary = self.image.stored_secondary(hash);
                let words = self.image.slab_mut(slab);
                for (w, &v) in item.iter().enumerate() {
                    words[l.item_word(slot, w as u32) as usize] = v;
                }
                let h = l.hashes as usize;
                match l.variant {
                    HashVariant::Atomic64 => {}
                    HashVariant::TicketBoard => words[SLAB_OCCUPANCY as usize] |= 1 << slot,
                    HashVariant::AccelHash32 => {
                        words[SLAB_OCCUPANCY as usize] |= 1 << slot;
                        words[h + slot as usize] = secondary;
                    }
                    HashVariant::AccelHash8 => {
                        words[SLAB_OCCUPANCY as usize] |= 1 << slot;
                        words[h + slot as usize / 4] |= secondary << (8 * (slot % 4));
                    }
                }
                return Ok(Handle::new(slab, slot));
            }
            prev = Some(slab);
            link = self.image.slab(slab).expect("linked slab")[SLAB_NEXT as usize];
        }
    }

    /// Finds or inserts every item (`item_words` words each), in order.
    pub fn find_or_insert(&mut self, items: &[u32]) -> Result<Vec<Handle>, HashError> {
        let w = self.image.layout.item_words as usize;
        items
            .chunks(w)
            .enumerate()
            .map(|(i, item)| {
                self.check(item, i)?;
                match self.search(item) {
                    Some(h) => Ok(h),
                    None => self.insert(item),
                }
            })
            .collect()
    }

    /// The item named by a handle.
    pub fn read(&self, handle: Handle) -> Option<Vec<u32>> {
        self.image.read(handle)
    }

    /// Lowest free slab; adds a super block when the pool is full.
    fn alloc_slab(&mut self) -> u32 {
        let found = self
            .image
            .super_blocks
            .iter()
            .enumerate()
            .find_map(|(sb, b)| {
                b[..SUPER_BLOCK_BITMASK_WORDS as usize]
                    .iter()
                    .position(|&m| m != u32::MAX)
                    .map(|wi| (sb, wi, b[wi].trailing_ones()))
            });
        let (sb, wi, bit) = found.unwrap_or_else(|| {
            self.image.grow(1);
            (self.image.super_blocks.len() - 1, 0, 0)
        });
        self.image.super_blocks[sb][wi] |= 1 << bit;
        self.image.status.allocated_slabs += 1;
        sb as u32 * SLABS_PER_SUPER_BLOCK + wi as u32 * 32 + bit
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hash::layout::MAX_ITEM_WORDS;

    fn items(n: u32, w: u32, seed: u32) -> Vec<u32> {
        (0..n * w)
            .map(|i| crate::hash::layout::fmix32(i ^ seed.wrapping_mul(0x9e37_79b9)) | 1)
            .collect()
    }

    #[test]
    fn reference_finds_what_it_inserted_and_walks_clean() {
        for v in HashVariant::ALL {
            for w in 1..=MAX_ITEM_WORDS {
                let mut t = ReferenceTable::new(v, w, 7).unwrap();
                let data = items(300, w, w);
                let handles = t.find_or_insert(&data).unwrap();
                for (item, h) in data.chunks(w as usize).zip(&handles) {
                    assert_eq!(t.search(item), Some(*h));
                    assert_eq!(t.read(*h).as_deref(), Some(item));
                }
                let again = t.find_or_insert(&data).unwrap();
                assert_eq!(again, handles, "{v:?} w={w}");
                let absent = items(50, w, 1000 + w);
                for item in absent.chunks(w as usize) {
                    assert_eq!(t.search(item), None);
                }
                let walk = t.image().walk().unwrap();
                assert_eq!(walk.items.len(), 300);
                assert!(walk.max_chain >= 300 / 7 / 32);
            }
        }
    }

    #[test]
    fn reference_rejects_zero_prefix_in_atomic64_only() {
        let mut a = ReferenceTable::new(HashVariant::Atomic64, 3, 4).unwrap();
        assert!(matches!(
            a.insert(&[0, 0, 5]),
            Err(HashError::InvalidItem { .. })
        ));
        assert!(a.insert(&[0, 1, 0]).is_ok());
        let mut t = ReferenceTable::new(HashVariant::TicketBoard, 3, 4).unwrap();
        let h = t.insert(&[0, 0, 0]).unwrap();
        assert_eq!(t.read(h), Some(vec![0, 0, 0]));
        assert_eq!(t.search(&[0, 0, 0]), Some(h));
    }

    #[test]
    fn walk_detects_corruption() {
        let mut t = ReferenceTable::new(HashVariant::AccelHash8, 2, 3).unwrap();
        t.find_or_insert(&items(100, 2, 9)).unwrap();
        let good = t.image().clone();
        assert!(good.walk().is_ok());
        // A slab leaked from the bitmask.
        let mut leaked = good.clone();
        leaked.super_blocks[0][0] &= !1;
        assert!(leaked.walk().is_err());
        // An item moved to a wrong bucket's slab: flip an item word.
        let mut moved = good.clone();
        let slab = moved.heads[0] - 1;
        let word = moved.layout.item_word(0, 0) as usize;
        moved.slab_mut(slab)[word] ^= 0x100;
        assert!(moved.walk().is_err());
    }
}
