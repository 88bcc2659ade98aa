//! The Vulkan device layer: the only module that uses `ash`.
//!
//! - [`GpuContext`]: instance, device selection (discrete > integrated > virtual > other > CPU;
//!   `VOXDAG_DEVICE=<substring>` overrides; every feature the shaders use is checked), validation
//!   (with synchronization validation) messenger, gpu-allocator, the queue's timeline semaphore,
//!   the deferred-release queue, the staging rings and submission statistics.
//! - [`Buffer`] (device addresses, may exceed `maxStorageBufferRange`), [`Image`] (RGBA8 storage),
//!   uploads and readbacks.
//! - [`ComputePipeline`] from embedded SPIR-V ([`shaders`]) with specialization and push constants.
//! - [`Commands`]: a recorder (pooled command buffer) for any number of passes, submitted once;
//!   its completion is a timeline value ([`Submission`]).
//! - [`FrameRing`]: N frames in flight, each waiting only for its own slot's last submission.
//! - [`Profiler`]: timestamp queries per pass, CPU spans, a table and Chrome trace JSON.
//! - [`Surface`] and [`Presenter`]: a window's surface, its swapchain, frames in flight, the blit
//!   of a compute image to the screen and an egui overlay (`voxdag view`).
//!
//! Lifetime rule: every object holds an `Arc<GpuContext>`; dropping it queues its Vulkan handles
//! with the timeline value of the last submission, and the context destroys them once the GPU has
//! passed that value (wgpu-core's deferred release). See `docs/gpu.md`.

// Every public item of the GPU layer (generated shader constants included) is documented.
#![warn(missing_docs)]

mod clock;
mod commands;
mod context;
mod frame;
mod memory;
mod pipeline;
mod profiler;
mod release;
mod ring;
pub mod shaders;
mod surface;
mod swapchain;
/// Push constants of the test shaders (`shaders/glsl/test/`, `shaders::TEST_*`), for the
/// GPU-layer tests.
#[path = "gpu_shared.rs"]
pub mod test_layouts;

pub use clock::{thread_cpu_time, PhaseClock, PhaseTime};
pub use commands::{Bound, Commands, Readback, Submission};
pub use context::{DeviceInfo, DeviceType, GpuContext, GpuOptions, GpuStats, REQUIRED_FEATURES};
pub use frame::{FrameRing, DEFAULT_FRAMES_IN_FLIGHT};
pub use memory::{Buffer, BufferSlice, Image, MemLocation, TexelBuffer, WordTexels};
pub use pipeline::{made_once, BindingKind, ComputePipeline, ComputePipelineDesc};
pub use profiler::{CpuSpan, PassTiming, Profiler};
pub use surface::Surface;
pub use swapchain::{FrameSlot, OverlayFrame, Presenter, PresenterOptions, PresenterStats};

use std::path::PathBuf;

/// Errors of the GPU layer.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// The Vulkan loader is missing or too old.
    #[error("Vulkan unavailable: {0}")]
    NoVulkan(String),
    /// No device has what voxdag needs.
    #[error("no usable Vulkan device: {0}")]
    NoDevice(String),
    /// `VOXDAG_DEVICE` (or `GpuOptions::device`) matches no usable device.
    #[error("no usable Vulkan device matches {wanted:?}; devices: {available}")]
    DeviceNotFound {
        /// The requested substring.
        wanted: String,
        /// All devices found, with their types.
        available: String,
    },
    /// The device lacks a feature voxdag's shaders or host code need.
    #[error("device \"{device}\" is unsupported: it lacks {feature}")]
    Unsupported {
        /// The device.
        device: String,
        /// The missing feature, as Vulkan names it (e.g. `shaderBufferInt64Atomics`).
        feature: String,
    },
    /// The device was lost (driver reset, hang, removal): recreate the context.
    #[error("Vulkan device lost")]
    DeviceLost,
    /// Device memory is exhausted (free resources, e.g. run GC, and retry).
    #[error("out of device memory{0}")]
    OutOfDeviceMemory(String),
    /// Host memory is exhausted.
    #[error("out of host memory{0}")]
    OutOfHostMemory(String),
    /// The window surface is gone (recreate the surface).
    #[error("Vulkan surface lost")]
    SurfaceLost,
    /// The swapchain no longer matches the surface (recreate the swapchain).
    #[error("swapchain out of date")]
    OutOfDate,
    /// Any other failed Vulkan call, with its `VkResult`.
    #[error("{call} failed: {result:?}")]
    Vulkan {
        /// The Vulkan function.
        call: &'static str,
        /// The `VkResult`.
        result: ash::vk::Result,
    },
    /// Device memory allocation failed for a reason other than exhaustion.
    #[error("allocating '{name}' failed: {message}")]
    Allocation {
        /// Name of the buffer or image.
        name: String,
        /// What the allocator said.
        message: String,
    },
    /// A buffer larger than the device's `maxMemoryAllocationSize` (paging comes later).
    #[error("buffer '{name}' of {size} bytes exceeds the device's maximum allocation size of {max} bytes")]
    TooLarge {
        /// Buffer name.
        name: String,
        /// Requested size in bytes.
        size: u64,
        /// `maxMemoryAllocationSize`.
        max: u64,
    },
    /// A read or write outside a buffer.
    #[error("range {offset}+{len} is outside buffer '{name}' of {size} bytes")]
    OutOfRange {
        /// Buffer name.
        name: String,
        /// Byte offset.
        offset: u64,
        /// Length in bytes.
        len: u64,
        /// Buffer size in bytes.
        size: u64,
    },
    /// An argument the GPU layer cannot use (sizes, push-constant length, ...).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// Creating or using a window surface or swapchain failed (no presentation support, surface
    /// lost, ...).
    #[error("presentation: {0}")]
    Surface(String),
    /// Writing a file (e.g. a trace) failed.
    #[error("writing {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

impl GpuError {
    /// Maps a failed Vulkan call's `VkResult` to the error a caller can act on: device lost,
    /// out of device / host memory, surface lost, swapchain out of date; anything else keeps its
    /// `VkResult` in [`GpuError::Vulkan`].
    pub fn from_vk(call: &'static str, result: ash::vk::Result) -> GpuError {
        use ash::vk::Result as R;
        match result {
            R::ERROR_DEVICE_LOST => GpuError::DeviceLost,
            R::ERROR_OUT_OF_DEVICE_MEMORY => GpuError::OutOfDeviceMemory(format!(" ({call})")),
            R::ERROR_OUT_OF_HOST_MEMORY => GpuError::OutOfHostMemory(format!(" ({call})")),
            R::ERROR_SURFACE_LOST_KHR => GpuError::SurfaceLost,
            R::ERROR_OUT_OF_DATE_KHR => GpuError::OutOfDate,
            result => GpuError::Vulkan { call, result },
        }
    }

    /// Maps a gpu-allocator failure for the named resource: exhaustion becomes
    /// [`GpuError::OutOfDeviceMemory`] / [`GpuError::OutOfHostMemory`], the rest
    /// [`GpuError::Allocation`].
    pub fn from_allocation(name: &str, error: gpu_allocator::AllocationError) -> GpuError {
        use gpu_allocator::AllocationError as A;
        match error {
            A::OutOfMemory => GpuError::OutOfDeviceMemory(format!(" (allocating '{name}')")),
            // gpu-allocator reports vkAllocateMemory's other failures as text.
            A::Internal(m) if m.contains("ERROR_OUT_OF_HOST_MEMORY") => {
                GpuError::OutOfHostMemory(format!(" (allocating '{name}')"))
            }
            A::Internal(m) if m.contains("ERROR_OUT_OF_DEVICE_MEMORY") => {
                GpuError::OutOfDeviceMemory(format!(" (allocating '{name}')"))
            }
            e => GpuError::Allocation {
                name: name.to_string(),
                message: e.to_string(),
            },
        }
    }
}

/// Maps an `ash` error to a [`GpuError`] for the named call ([`GpuError::from_vk`]).
pub(crate) fn vk_err(call: &'static str) -> impl Fn(ash::vk::Result) -> GpuError {
    move |e| GpuError::from_vk(call, e)
}
