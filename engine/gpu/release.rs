//! Deferred release (as wgpu-core does it): a Vulkan object dropped while the GPU may still use
//! it is queued with the timeline value of the last submission and destroyed (or, for command
//! recorders, reset and reused) once the queue's timeline semaphore has passed that value.

use ash::vk;
use gpu_allocator::vulkan::Allocation;

use super::ring::RingKind;
use super::MemLocation;

/// A command pool with its one primary command buffer and the descriptor pools its recordings
/// allocated from; reset and reused once its submission has completed.
pub(crate) struct Recorder {
    pub(crate) pool: vk::CommandPool,
    pub(crate) buffer: vk::CommandBuffer,
    /// Descriptor pools, grown on demand (each twice the previous), reset with the recorder.
    pub(crate) descriptor_pools: Vec<vk::DescriptorPool>,
    /// Index of the pool new sets come from.
    pub(crate) current_pool: usize,
    /// Sets allocated from the current pool (a pool of index `i` holds `64 << i`; counted here
    /// because drivers may allocate beyond `maxSets` instead of failing).
    pub(crate) current_sets: u32,
}

/// What a dropped buffer of a reusable size class needs to be handed out again
/// (`GpuContext::create_buffer`).
pub(crate) struct Recyclable {
    /// The size class (the Vulkan buffer's size).
    pub(crate) class: u64,
    /// Memory location it was allocated for.
    pub(crate) location: MemLocation,
    /// Its device address.
    pub(crate) address: u64,
}

/// Something whose destruction waits for the GPU.
pub(crate) enum Garbage {
    /// A buffer and its memory; with its size class, it goes to the free buffers for reuse.
    Buffer(vk::Buffer, Allocation, Option<Recyclable>),
    /// A texel buffer's view (its buffer is released on its own).
    BufferView(vk::BufferView),
    /// An image, its view and its memory.
    Image(vk::Image, vk::ImageView, Allocation),
    /// A pipeline, its layout and its set layout.
    Pipeline(
        vk::Pipeline,
        vk::PipelineLayout,
        Option<vk::DescriptorSetLayout>,
    ),
    /// A timestamp query pool.
    QueryPool(vk::QueryPool),
    /// A command recorder, reused once released.
    Recorder(Recorder),
    /// A staging-ring region.
    RingRegion(RingKind, u64),
}

/// Most bytes the free buffers may hold; a dropped buffer beyond it is destroyed.
const FREE_BUFFER_BUDGET: u64 = 64 << 20;

/// A kept buffer: the Vulkan buffer, its allocation and its device address.
pub(crate) type KeptBuffer = (vk::Buffer, Allocation, u64);

/// Dropped buffers kept for reuse, per size class and memory location (most recently kept
/// first out, so a steady loop of creating and dropping reuses the same few).
#[derive(Default)]
pub(crate) struct FreeBuffers {
    lists: Vec<((u64, MemLocation), Vec<KeptBuffer>)>,
    bytes: u64,
}

impl FreeBuffers {
    /// Keeps a buffer for reuse; gives it back when the budget is full.
    pub(crate) fn keep(
        &mut self,
        raw: vk::Buffer,
        allocation: Allocation,
        r: Recyclable,
    ) -> Option<(vk::Buffer, Allocation)> {
        if self.bytes + r.class > FREE_BUFFER_BUDGET {
            return Some((raw, allocation));
        }
        self.bytes += r.class;
        let key = (r.class, r.location);
        let entry = (raw, allocation, r.address);
        match self.lists.iter_mut().find(|(k, _)| *k == key) {
            Some((_, list)) => list.push(entry),
            None => self.lists.push((key, vec![entry])),
        }
        None
    }

    /// A kept buffer of size class `class` in `location`.
    pub(crate) fn take(&mut self, class: u64, location: MemLocation) -> Option<KeptBuffer> {
        let (_, list) = self
            .lists
            .iter_mut()
            .find(|(k, _)| *k == (class, location))?;
        let entry = list.pop()?;
        self.bytes -= class;
        Some(entry)
    }

    /// Every kept buffer, to destroy.
    pub(crate) fn drain(&mut self) -> Vec<(vk::Buffer, Allocation)> {
        self.bytes = 0;
        self.lists
            .drain(..)
            .flat_map(|(_, list)| list)
            .map(|(raw, allocation, _)| (raw, allocation))
            .collect()
    }
}
