//! The Vulkan device layer: the only module that uses `ash`.
//!
//! - [`GpuContext`]: instance, device selection (discrete > integrated > virtual > other > CPU;
//!   `VOXDAG_DEVICE=<substring>` overrides), validation messenger, gpu-allocator.
//! - [`Buffer`] (device addresses, may exceed `maxStorageBufferRange`), [`Image`] (RGBA8 storage),
//!   uploads and readbacks.
//! - [`ComputePipeline`] from embedded SPIR-V ([`shaders`]) with specialization and push constants.
//! - [`Commands`]: one-shot command buffers, submitted and waited on with a fence.
//! - [`Profiler`]: timestamp queries per pass, CPU spans, a table and Chrome trace JSON.
//! - [`Surface`] and [`Presenter`]: a window's surface, its swapchain, frames in flight, the blit
//!   of a compute image to the screen and an egui overlay (`voxdag view`).
//!
//! Lifetime rule: every object holds an `Arc<GpuContext>` and destroys its Vulkan handles once,
//! on drop; submissions wait for their fence, so nothing is in flight when a resource drops.
//! See `docs/gpu.md`.

// Every public item of the GPU layer (generated shader constants included) is documented.
#![warn(missing_docs)]

mod commands;
mod context;
mod memory;
mod pipeline;
mod profiler;
pub mod shaders;
mod surface;
mod swapchain;

pub use commands::Commands;
pub use context::{DeviceInfo, GpuContext, GpuOptions};
pub use memory::{Buffer, Image, MemLocation};
pub use pipeline::{ComputePipeline, ComputePipelineDesc};
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
    /// A Vulkan call failed.
    #[error("{call} failed: {result}")]
    Vulkan {
        /// The Vulkan function.
        call: &'static str,
        /// The `VkResult` (and context).
        result: String,
    },
    /// Device memory allocation failed.
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

/// Maps an `ash` error to [`GpuError::Vulkan`] for the named call.
pub(crate) fn vk_err(call: &'static str) -> impl Fn(ash::vk::Result) -> GpuError {
    move |e| GpuError::Vulkan {
        call,
        result: format!("{e:?}"),
    }
}
