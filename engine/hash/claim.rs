//! The claim table: a batch's duplicate detection folded into the table's own passes, for
//! single lanes (CPU devices such as lavapipe, `TeamMode::SingleLane`).
//!
//! A find-or-insert of a batch that may hold equal items must store each distinct item once.
//! The general route is a separate duplicate-detection table ([`super::dedup`]: three passes)
//! followed by the table's search, a mark pass and the insert. With single lanes two passes
//! do it all ([`GpuHashTable::record_search_claim`](super::GpuHashTable::record_search_claim),
//! [`GpuHashTable::record_claimed_insert_round`](super::GpuHashTable::record_claimed_insert_round)):
//! 1. *search and claim*: every item is searched in the table; a missing one also makes sure
//!    the claim table holds a copy of it (open addressing with linear probing, the hash in the
//!    tag, the writing item's index as the copy's owner);
//! 2. *claimed insert round*: every missing item looks up the first copy along its probe
//!    sequence (the claim table no longer changes, so equal items find the same one); its owner
//!    is the representative: only it is inserted, the others get [`HANDLE_INVALID`] and the
//!    owner's index in `reps`.
//!
//! Layout (`shaders/glsl/hash/claims.glsl`): `tags[slots] | owners[slots] | items[slots][words]`,
//! `slots` a power of two at least twice the items (it never fills up); only the tags are
//! zeroed ([`ClaimTable::record_clear`]). Single lanes only: the cooperative subgroup passes keep
//! the slab dedup table of the dissertation (§4.4.2).
//!
//! [`HANDLE_INVALID`]: super::HANDLE_INVALID

use std::sync::Arc;

use super::dedup::DedupLayout;
use super::layout::HashPush;
use super::HashError;
use crate::gpu::{Buffer, BufferSlice, Commands, GpuContext, MemLocation};

/// What the claim passes of one batch use: its claim table and the representatives (one `u32`
/// per item: the index of the item whose handle is this item's).
#[derive(Clone, Copy, Debug)]
pub struct Claims<'a> {
    /// The batch's claim table.
    pub table: &'a ClaimTable,
    /// The representatives (one `u32` per item).
    pub reps: BufferSlice<'a>,
}

impl Claims<'_> {
    /// Names the claim table and the representatives in a pass's push constants.
    pub(super) fn fill_push(self, push: &mut HashPush) {
        push.claims = self.table.address();
        push.claim_slots = self.table.slot_count();
        push.reps = self.reps.address();
    }
}

/// The claim table of one batch (see the module docs).
#[derive(Debug)]
pub struct ClaimTable {
    table: Buffer,
    slots: u32,
    item_words: u32,
    capacity: u32,
}

impl ClaimTable {
    /// The layout it shares with the dedup table's probe form (tags, owners / values, keys).
    fn layout(item_words: u32) -> DedupLayout {
        DedupLayout {
            key_words: item_words,
            probe: true,
        }
    }

    /// Slots for `count` items: a power of two, at least twice the items; `None` when the
    /// table's words would not fit the shaders' 32-bit indices.
    pub fn slots(count: u32, item_words: u32) -> Option<u32> {
        Self::layout(item_words).fitting_probe_slots(count)
    }

    /// A table for batches of up to `count` items of `item_words` words.
    pub fn new(
        ctx: &Arc<GpuContext>,
        item_words: u32,
        count: u32,
    ) -> Result<ClaimTable, HashError> {
        let slots = Self::slots(count, item_words).ok_or_else(|| {
            HashError::InvalidArgument(format!(
                "{count} items of {item_words} words are too many for one claim table"
            ))
        })?;
        let bytes = 4 * Self::layout(item_words).probe_words(slots);
        Ok(ClaimTable {
            table: ctx.create_buffer("hash claim table", bytes, MemLocation::GpuOnly)?,
            slots,
            item_words,
            capacity: count,
        })
    }

    /// Records the zeroing of the tags (before every batch's search-and-claim pass).
    pub fn record_clear<'a>(&'a self, cmd: &mut Commands<'a>) -> Result<(), HashError> {
        cmd.fill_range(&self.table, 0, 4 * self.slots as u64, 0)?;
        Ok(())
    }

    /// Device address of the table (`HashPush::claims`).
    pub fn address(&self) -> u64 {
        self.table.address()
    }

    /// Slots (`HashPush::claim_slots`).
    pub fn slot_count(&self) -> u32 {
        self.slots
    }

    /// Checks that a batch of `count` items of `item_words` words fits this table.
    pub(super) fn check_batch(&self, count: u32, item_words: u32) -> Result<(), HashError> {
        if item_words != self.item_words || count > self.capacity {
            return Err(HashError::InvalidArgument(format!(
                "claim table for {} items of {} words used for {count} items of {item_words}",
                self.capacity, self.item_words
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::ClaimTable;

    #[test]
    fn claim_tables_have_a_power_of_two_of_at_least_twice_the_items() {
        assert_eq!(ClaimTable::slots(0, 2), Some(2));
        assert_eq!(ClaimTable::slots(1, 2), Some(2));
        assert_eq!(ClaimTable::slots(3, 9), Some(8));
        assert_eq!(ClaimTable::slots(1024, 9), Some(2048));
        // 2^28 slots of 2 + 14 words pass 2^32 words.
        assert_eq!(ClaimTable::slots(1 << 27, 14), None);
        assert_eq!(ClaimTable::slots(1 << 27, 10), Some(1 << 28));
    }
}
