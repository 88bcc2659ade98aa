//! Deferred release (as wgpu-core does it): a Vulkan object dropped while the GPU may still use
//! it is queued with the timeline value of the last submission and destroyed (or, for command
//! recorders, reset and reused) once the queue's timeline semaphore has passed that value.

use ash::vk;
use gpu_allocator::vulkan::Allocation;

use super::ring::RingKind;

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

/// Something whose destruction waits for the GPU.
pub(crate) enum Garbage {
    /// A buffer and its memory.
    Buffer(vk::Buffer, Allocation),
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
