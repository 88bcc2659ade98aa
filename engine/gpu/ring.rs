//! Persistent host-visible staging rings: one for uploads, one for readbacks.
//!
//! A ring is one mapped buffer carved into regions in allocation order. A region is freed when
//! the GPU is done with it (uploads: once the submission that copies from it has completed;
//! readbacks: once the host has read it, or its submission completed unread), in any order;
//! space is reclaimed from the oldest region on. Transfers that do not fit fall back to a
//! dedicated staging buffer, so a full ring is never an error.

use std::collections::VecDeque;

use ash::vk;
use gpu_allocator::vulkan::Allocation;

/// Offsets and sizes of ring regions are multiples of this (covers `nonCoherentAtomSize` and
/// `minMemoryMapAlignment` on every device; ring memory is host-coherent anyway).
pub(crate) const RING_ALIGN: u64 = 256;

/// Which ring a region belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RingKind {
    /// Host writes, GPU copies out.
    Upload,
    /// GPU copies in, host reads.
    Readback,
}

/// Region bookkeeping of one ring (no Vulkan: unit-tested on its own).
#[derive(Debug)]
pub(crate) struct RingAlloc {
    capacity: u64,
    /// (id, start, end, freed), oldest first.
    regions: VecDeque<(u64, u64, u64, bool)>,
    next_id: u64,
}

impl RingAlloc {
    /// An empty ring of `capacity` bytes.
    pub(crate) fn new(capacity: u64) -> RingAlloc {
        RingAlloc {
            capacity,
            regions: VecDeque::new(),
            next_id: 1,
        }
    }

    /// Reserves `len` bytes (rounded up to [`RING_ALIGN`]); `(id, offset)` or `None` when the
    /// free space at the head is too small.
    pub(crate) fn alloc(&mut self, len: u64) -> Option<(u64, u64)> {
        let len = len.max(1).div_ceil(RING_ALIGN) * RING_ALIGN;
        if len > self.capacity {
            return None;
        }
        let start = match (self.regions.front(), self.regions.back()) {
            (Some(&(_, tail, _, _)), Some(&(_, back_start, head, _))) => {
                if back_start >= tail {
                    // Not wrapped: space after the head, else from 0 up to the tail.
                    if head + len <= self.capacity {
                        head
                    } else if len <= tail {
                        0
                    } else {
                        return None;
                    }
                } else if head + len <= tail {
                    head
                } else {
                    return None;
                }
            }
            _ => 0,
        };
        let id = self.next_id;
        self.next_id += 1;
        self.regions.push_back((id, start, start + len, false));
        Some((id, start))
    }

    /// Frees a region (any order); space is reclaimed once all older regions are free too.
    pub(crate) fn free(&mut self, id: u64) {
        if let Some(r) = self.regions.iter_mut().find(|r| r.0 == id) {
            r.3 = true;
        }
        while self.regions.front().is_some_and(|r| r.3) {
            self.regions.pop_front();
        }
    }

    /// Regions not yet freed.
    #[cfg(test)]
    pub(crate) fn live(&self) -> usize {
        self.regions.iter().filter(|r| !r.3).count()
    }
}

/// A ring: its mapped buffer and its regions.
pub(crate) struct Ring {
    pub(crate) raw: vk::Buffer,
    pub(crate) allocation: Option<Allocation>,
    pub(crate) alloc: RingAlloc,
}

impl Ring {
    /// Mapped pointer to byte `offset` (the ring's allocation is persistently mapped).
    pub(crate) fn ptr(&self, offset: u64) -> *mut u8 {
        match self.allocation.as_ref().and_then(|a| a.mapped_ptr()) {
            // SAFETY: offsets come from `alloc`, inside the mapped buffer.
            Some(p) => unsafe { (p.as_ptr() as *mut u8).add(offset as usize) },
            None => std::ptr::null_mut(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_wraps_and_reclaims_in_order() {
        let mut r = RingAlloc::new(1024);
        let (a, oa) = r.alloc(300).unwrap(); // 512 bytes at 0
        let (b, ob) = r.alloc(256).unwrap(); // 256 at 512
        assert_eq!((oa, ob), (0, 512));
        assert!(r.alloc(512).is_none(), "only 256 bytes left at the head");
        let (c, oc) = r.alloc(200).unwrap();
        assert_eq!(oc, 768);
        // Freeing b first reclaims nothing (a is older and live).
        r.free(b);
        assert!(r.alloc(1).is_none());
        r.free(a);
        // a and b reclaimed: wrap to 0, up to c's start.
        let (d, od) = r.alloc(700).unwrap();
        assert_eq!(od, 0);
        assert!(r.alloc(256).is_none(), "768..1024 is c, 0..768 is d");
        r.free(c);
        r.free(d);
        assert_eq!(r.live(), 0);
        assert_eq!(r.alloc(1024).unwrap().1, 0);
        assert!(r.alloc(2048).is_none());
    }
}
