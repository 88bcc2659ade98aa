//! One-shot command buffers: record dispatches, copies and barriers, submit and wait on a fence.

use std::ffi::CString;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Arc;

use ash::vk;

use super::memory::color_range;
use super::{vk_err, Buffer, ComputePipeline, GpuContext, GpuError, Image};

/// Where a [`Commands`] is in its life; shared with the [`super::Profiler`], which discards the
/// passes of a command buffer that was dropped without a successful submit instead of waiting
/// for timestamps that will never be written.
#[derive(Debug, Default)]
pub(crate) struct Lifecycle(AtomicU8);

/// States stored in a [`Lifecycle`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum CommandsState {
    /// Being recorded (or submitted and not yet waited on).
    Recording,
    /// Submitted, and the GPU has finished it.
    Finished,
    /// Dropped without a completed submission: nothing it recorded ran (or will be read).
    Abandoned,
}

impl Lifecycle {
    /// The current state.
    pub(crate) fn get(&self) -> CommandsState {
        match self.0.load(Ordering::Acquire) {
            0 => CommandsState::Recording,
            1 => CommandsState::Finished,
            _ => CommandsState::Abandoned,
        }
    }

    pub(crate) fn set(&self, state: CommandsState) {
        let v = match state {
            CommandsState::Recording => 0,
            CommandsState::Finished => 1,
            CommandsState::Abandoned => 2,
        };
        self.0.store(v, Ordering::Release);
    }
}

/// A command buffer being recorded. Resources passed by reference must outlive it (`'a`);
/// buffers reached only through device addresses must be kept alive by the caller until
/// [`Commands::submit`] returns. Dropping it unsubmitted frees it without running anything.
///
/// Thread safety: Vulkan requires a command pool to be externally synchronised while any of its
/// command buffers is allocated, recorded, ended or freed. Rather than one pool in the shared
/// [`GpuContext`] whose mutex would have to stay locked for the whole life of every recorder
/// (serialising all threads, and deadlocking a thread that starts an upload while it records),
/// each `Commands` creates its own transient pool and destroys it on drop. Nothing else ever
/// touches that pool, so recorders on different threads need no lock at all; only the queue is
/// locked, for the submit itself. A pool per one-shot submission costs far less than the fence
/// wait that follows it.
pub struct Commands<'a> {
    pub(crate) raw: vk::CommandBuffer,
    pool: vk::CommandPool,
    fence: vk::Fence,
    descriptor_pool: vk::DescriptorPool,
    name: String,
    /// Submitted and not yet known to be finished.
    pending: bool,
    /// Shared with the profiler's passes recorded here.
    pub(crate) lifecycle: Arc<Lifecycle>,
    pub(crate) ctx: Arc<GpuContext>,
    _resources: PhantomData<&'a ()>,
}

impl GpuContext {
    /// Starts recording a named one-shot command buffer (any thread may record its own at once).
    pub fn begin_commands<'a>(self: &Arc<Self>, name: &str) -> Result<Commands<'a>, GpuError> {
        let device = &self.device;
        // Null handles until created: `Drop` destroys whatever exists if a step below fails.
        let mut cmd = Commands {
            raw: vk::CommandBuffer::null(),
            pool: vk::CommandPool::null(),
            fence: vk::Fence::null(),
            descriptor_pool: vk::DescriptorPool::null(),
            name: name.to_string(),
            pending: false,
            lifecycle: Arc::new(Lifecycle::default()),
            ctx: Arc::clone(self),
            _resources: PhantomData,
        };
        // SAFETY: the pool, its command buffer and the fence are created here and owned by `cmd`
        // alone (see the type's docs), so no other thread can use them.
        unsafe {
            let pool_info = vk::CommandPoolCreateInfo::default()
                .queue_family_index(self.queue_family)
                .flags(vk::CommandPoolCreateFlags::TRANSIENT);
            cmd.pool = device
                .create_command_pool(&pool_info, None)
                .map_err(vk_err("vkCreateCommandPool"))?;
            let info = vk::CommandBufferAllocateInfo::default()
                .command_pool(cmd.pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            cmd.raw = device
                .allocate_command_buffers(&info)
                .map_err(vk_err("vkAllocateCommandBuffers"))?[0];
            cmd.fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .map_err(vk_err("vkCreateFence"))?;
            device
                .begin_command_buffer(
                    cmd.raw,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .map_err(vk_err("vkBeginCommandBuffer"))?;
        }
        self.set_name(cmd.pool, &format!("{name} (pool)"));
        self.set_name(cmd.raw, name);
        self.set_name(cmd.fence, &format!("{name} (fence)"));
        Ok(cmd)
    }
}

impl<'a> Commands<'a> {
    /// Name given at [`GpuContext::begin_commands`].
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Records a compute dispatch of `groups` workgroups with the given push-constant bytes and,
    /// if the pipeline uses one, the storage image at set 0, binding 0.
    pub fn dispatch(
        &mut self,
        pipeline: &'a ComputePipeline,
        groups: [u32; 3],
        push_constants: &[u8],
        image: Option<&'a Image>,
    ) -> Result<(), GpuError> {
        if push_constants.len() as u32 != pipeline.push_constant_size {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{}' expects {} push-constant bytes, got {}",
                pipeline.name(),
                pipeline.push_constant_size,
                push_constants.len()
            )));
        }
        let max = self.ctx.info().max_compute_workgroup_count;
        if groups.iter().zip(max).any(|(&g, m)| g > m) {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{}': {groups:?} workgroups exceed the device limit {max:?}",
                pipeline.name()
            )));
        }
        let set = match (pipeline.set_layout, image) {
            (Some(layout), Some(img)) => Some(self.image_set(layout, img)?),
            (None, None) => None,
            (Some(_), None) => {
                return Err(GpuError::InvalidArgument(format!(
                    "pipeline '{}' needs a storage image",
                    pipeline.name()
                )))
            }
            (None, Some(_)) => {
                return Err(GpuError::InvalidArgument(format!(
                    "pipeline '{}' takes no storage image",
                    pipeline.name()
                )))
            }
        };
        let device = &self.ctx.device;
        // SAFETY: recording into our command buffer with objects of this device.
        unsafe {
            device.cmd_bind_pipeline(self.raw, vk::PipelineBindPoint::COMPUTE, pipeline.raw);
            if let Some(set) = set {
                device.cmd_bind_descriptor_sets(
                    self.raw,
                    vk::PipelineBindPoint::COMPUTE,
                    pipeline.layout,
                    0,
                    &[set],
                    &[],
                );
            }
            if !push_constants.is_empty() {
                device.cmd_push_constants(
                    self.raw,
                    pipeline.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    push_constants,
                );
            }
            if groups.iter().all(|&g| g > 0) {
                device.cmd_dispatch(self.raw, groups[0], groups[1], groups[2]);
            }
        }
        Ok(())
    }

    /// Allocates and writes a descriptor set binding `image` (pool created lazily, freed on drop).
    fn image_set(
        &mut self,
        layout: vk::DescriptorSetLayout,
        image: &Image,
    ) -> Result<vk::DescriptorSet, GpuError> {
        let device = &self.ctx.device;
        // SAFETY: the pool belongs to this command buffer and lives until it is dropped.
        unsafe {
            if self.descriptor_pool == vk::DescriptorPool::null() {
                let sizes = [vk::DescriptorPoolSize {
                    ty: vk::DescriptorType::STORAGE_IMAGE,
                    descriptor_count: 64,
                }];
                self.descriptor_pool = device
                    .create_descriptor_pool(
                        &vk::DescriptorPoolCreateInfo::default()
                            .max_sets(64)
                            .pool_sizes(&sizes),
                        None,
                    )
                    .map_err(vk_err("vkCreateDescriptorPool"))?;
                self.ctx.set_name(
                    self.descriptor_pool,
                    &format!("{} (descriptors)", self.name),
                );
            }
            let layouts = [layout];
            let set = device
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default()
                        .descriptor_pool(self.descriptor_pool)
                        .set_layouts(&layouts),
                )
                .map_err(vk_err("vkAllocateDescriptorSets"))?[0];
            let image_info = [vk::DescriptorImageInfo {
                sampler: vk::Sampler::null(),
                image_view: image.view,
                image_layout: vk::ImageLayout::GENERAL,
            }];
            let write = vk::WriteDescriptorSet::default()
                .dst_set(set)
                .dst_binding(0)
                .descriptor_type(vk::DescriptorType::STORAGE_IMAGE)
                .image_info(&image_info);
            device.update_descriptor_sets(&[write], &[]);
            Ok(set)
        }
    }

    /// Full memory barrier: compute and transfer writes become visible to later compute,
    /// transfer and host accesses.
    pub fn barrier(&mut self) {
        let stages = vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER;
        let barrier = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(
                vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::TRANSFER_READ
                    | vk::AccessFlags::TRANSFER_WRITE,
            );
        // SAFETY: recording into our command buffer.
        unsafe {
            self.ctx.device.cmd_pipeline_barrier(
                self.raw,
                stages,
                stages,
                vk::DependencyFlags::empty(),
                &[barrier],
                &[],
                &[],
            );
        }
    }

    /// Copies `size` bytes between buffers (barriers before and after included).
    pub fn copy_buffer(
        &mut self,
        src: &'a Buffer,
        src_offset: u64,
        dst: &'a Buffer,
        dst_offset: u64,
        size: u64,
    ) -> Result<(), GpuError> {
        for (b, off) in [(src, src_offset), (dst, dst_offset)] {
            if off.checked_add(size).map_or(true, |e| e > b.size()) {
                return Err(GpuError::OutOfRange {
                    name: b.name().to_string(),
                    offset: off,
                    len: size,
                    size: b.size(),
                });
            }
        }
        self.barrier();
        let region = vk::BufferCopy {
            src_offset,
            dst_offset,
            size,
        };
        // SAFETY: ranges checked above; both buffers have TRANSFER usage.
        unsafe {
            self.ctx
                .device
                .cmd_copy_buffer(self.raw, src.raw, dst.raw, &[region]);
        }
        self.barrier();
        Ok(())
    }

    /// Fills a whole buffer with a repeated `u32` (size rounded down to 4 bytes).
    pub fn fill_buffer(&mut self, dst: &'a Buffer, value: u32) {
        self.barrier();
        // SAFETY: whole-size fill of a TRANSFER_DST buffer.
        unsafe {
            self.ctx
                .device
                .cmd_fill_buffer(self.raw, dst.raw, 0, vk::WHOLE_SIZE, value);
        }
        self.barrier();
    }

    /// Copies an RGBA8 image into a buffer (tightly packed rows, top row first).
    pub fn copy_image_to_buffer(&mut self, image: &'a Image, dst: &'a Buffer) {
        let all = vk::AccessFlags::SHADER_READ
            | vk::AccessFlags::SHADER_WRITE
            | vk::AccessFlags::TRANSFER_READ
            | vk::AccessFlags::TRANSFER_WRITE;
        let stages = vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER;
        self.image_layout(
            image,
            (
                vk::ImageLayout::GENERAL,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            ),
            (
                vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE,
                vk::AccessFlags::TRANSFER_READ,
            ),
            (stages, vk::PipelineStageFlags::TRANSFER),
        );
        self.barrier();
        let region = vk::BufferImageCopy {
            buffer_offset: 0,
            buffer_row_length: 0,
            buffer_image_height: 0,
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: 1,
            },
            image_offset: vk::Offset3D::default(),
            image_extent: vk::Extent3D {
                width: image.width(),
                height: image.height(),
                depth: 1,
            },
        };
        // SAFETY: the image was just moved to TRANSFER_SRC_OPTIMAL; dst size is checked by callers.
        unsafe {
            self.ctx.device.cmd_copy_image_to_buffer(
                self.raw,
                image.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                dst.raw,
                &[region],
            );
        }
        self.image_layout(
            image,
            (
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                vk::ImageLayout::GENERAL,
            ),
            (vk::AccessFlags::TRANSFER_READ, all),
            (vk::PipelineStageFlags::TRANSFER, stages),
        );
        self.barrier();
    }

    /// Records a layout transition of the whole image: (old, new) layouts, accesses and stages.
    fn image_layout(
        &mut self,
        image: &Image,
        layouts: (vk::ImageLayout, vk::ImageLayout),
        access: (vk::AccessFlags, vk::AccessFlags),
        stages: (vk::PipelineStageFlags, vk::PipelineStageFlags),
    ) {
        let barrier = vk::ImageMemoryBarrier::default()
            .src_access_mask(access.0)
            .dst_access_mask(access.1)
            .old_layout(layouts.0)
            .new_layout(layouts.1)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image.raw)
            .subresource_range(color_range());
        // SAFETY: recording into our command buffer; the caller states the image's current layout.
        unsafe {
            self.ctx.device.cmd_pipeline_barrier(
                self.raw,
                stages.0,
                stages.1,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier],
            );
        }
    }

    /// Transitions a new image from `UNDEFINED` to `GENERAL` and clears it to zero.
    pub(crate) fn init_image(&mut self, image: &'a Image) {
        self.image_layout(
            image,
            (vk::ImageLayout::UNDEFINED, vk::ImageLayout::GENERAL),
            (
                vk::AccessFlags::empty(),
                vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::TRANSFER_READ
                    | vk::AccessFlags::TRANSFER_WRITE,
            ),
            (
                vk::PipelineStageFlags::TOP_OF_PIPE,
                vk::PipelineStageFlags::TRANSFER | vk::PipelineStageFlags::COMPUTE_SHADER,
            ),
        );
        // SAFETY: recording into our command buffer; the image is now in GENERAL layout.
        unsafe {
            self.ctx.device.cmd_clear_color_image(
                self.raw,
                image.raw,
                vk::ImageLayout::GENERAL,
                &vk::ClearColorValue { uint32: [0; 4] },
                &[color_range()],
            );
        }
        self.barrier();
    }

    /// Opens a debug label (shown by RenderDoc / Nsight and in validation messages).
    pub fn begin_label(&mut self, name: &str) {
        if let Some(du) = &self.ctx.debug_device {
            let cname = CString::new(name.replace('\0', " ")).unwrap_or_default();
            let label = vk::DebugUtilsLabelEXT::default().label_name(&cname);
            // SAFETY: recording into our command buffer.
            unsafe { du.cmd_begin_debug_utils_label(self.raw, &label) };
        }
    }

    /// Closes the innermost debug label.
    pub fn end_label(&mut self) {
        if let Some(du) = &self.ctx.debug_device {
            // SAFETY: recording into our command buffer; labels are balanced by the caller.
            unsafe { du.cmd_end_debug_utils_label(self.raw) };
        }
    }

    /// Ends recording, submits, and waits for the GPU to finish (all writes visible to the host).
    pub fn submit(mut self) -> Result<(), GpuError> {
        let device = &self.ctx.device;
        let host_barrier = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        // SAFETY: the command buffer and fence are ours; the queue is locked while submitting,
        // and we wait for the fence before anything referenced may be dropped.
        unsafe {
            device.cmd_pipeline_barrier(
                self.raw,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[host_barrier],
                &[],
                &[],
            );
            device
                .end_command_buffer(self.raw)
                .map_err(vk_err("vkEndCommandBuffer"))?;
            let buffers = [self.raw];
            let submit = vk::SubmitInfo::default().command_buffers(&buffers);
            {
                let queue = self.ctx.queue();
                device
                    .queue_submit(*queue, &[submit], self.fence)
                    .map_err(vk_err("vkQueueSubmit"))?;
            }
            self.pending = true;
            device
                .wait_for_fences(&[self.fence], true, u64::MAX)
                .map_err(vk_err("vkWaitForFences"))?;
            self.pending = false;
        }
        self.lifecycle.set(CommandsState::Finished);
        Ok(())
    }
}

impl Drop for Commands<'_> {
    fn drop(&mut self) {
        if self.lifecycle.get() != CommandsState::Finished {
            self.lifecycle.set(CommandsState::Abandoned);
        }
        let device = &self.ctx.device;
        // SAFETY: either never submitted, or submitted and waited on (submit returns only after
        // the fence signalled; on a failed wait we wait for the whole device before destroying).
        // Null handles (creation failed half-way) are valid arguments to the destroy calls, and
        // destroying the pool frees its command buffer.
        unsafe {
            if self.pending {
                // Submitted but the wait failed (device lost?): make sure nothing runs any more.
                let _queue = self.ctx.queue();
                let _ = device.device_wait_idle();
            }
            device.destroy_fence(self.fence, None);
            device.destroy_descriptor_pool(self.descriptor_pool, None);
            device.destroy_command_pool(self.pool, None);
        }
    }
}

/// A command buffer ended by [`Commands::detach`], owned by a caller that submits it itself (the
/// frame ring of `swapchain.rs`, with its own semaphores) and keeps it until its fence signals.
pub(crate) struct DetachedCommands {
    /// The ended command buffer.
    pub(crate) raw: vk::CommandBuffer,
    /// Signalled by the caller's submission.
    pub(crate) fence: vk::Fence,
    pool: vk::CommandPool,
    descriptor_pool: vk::DescriptorPool,
    lifecycle: Arc<Lifecycle>,
    /// Submitted and not yet waited on.
    pub(crate) pending: bool,
    ctx: Arc<GpuContext>,
}

impl Commands<'_> {
    /// Ends recording and hands the command buffer, its fence and pools to the caller, who submits
    /// it (setting `pending`) and must keep every resource it references alive until
    /// [`DetachedCommands::wait`] returned.
    pub(crate) fn detach(mut self) -> Result<DetachedCommands, GpuError> {
        // SAFETY: our command buffer, in the recording state.
        unsafe { self.ctx.device.end_command_buffer(self.raw) }
            .map_err(vk_err("vkEndCommandBuffer"))?;
        let detached = DetachedCommands {
            raw: std::mem::replace(&mut self.raw, vk::CommandBuffer::null()),
            fence: std::mem::replace(&mut self.fence, vk::Fence::null()),
            pool: std::mem::replace(&mut self.pool, vk::CommandPool::null()),
            descriptor_pool: std::mem::replace(
                &mut self.descriptor_pool,
                vk::DescriptorPool::null(),
            ),
            // `self`'s Drop marks a fresh lifecycle abandoned, not the one the profiler watches.
            lifecycle: std::mem::take(&mut self.lifecycle),
            pending: false,
            ctx: Arc::clone(&self.ctx),
        };
        Ok(detached)
    }
}

impl DetachedCommands {
    /// Waits for the submission's fence (if submitted) and marks its profiler passes finished.
    pub(crate) fn wait(&mut self) -> Result<(), GpuError> {
        if self.pending {
            // SAFETY: the fence belongs to this device and was passed to a queue submission.
            unsafe {
                self.ctx
                    .device
                    .wait_for_fences(&[self.fence], true, u64::MAX)
            }
            .map_err(vk_err("vkWaitForFences"))?;
            self.pending = false;
            self.lifecycle.set(CommandsState::Finished);
        }
        Ok(())
    }
}

impl Drop for DetachedCommands {
    fn drop(&mut self) {
        if self.lifecycle.get() != CommandsState::Finished {
            self.lifecycle.set(CommandsState::Abandoned);
        }
        let device = &self.ctx.device;
        // SAFETY: as for `Commands`: never submitted, waited on, or the device is idled first.
        unsafe {
            if self.pending {
                let _queue = self.ctx.queue();
                let _ = device.device_wait_idle();
            }
            device.destroy_fence(self.fence, None);
            device.destroy_descriptor_pool(self.descriptor_pool, None);
            device.destroy_command_pool(self.pool, None);
        }
    }
}
