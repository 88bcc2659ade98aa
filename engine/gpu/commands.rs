//! The command recorder: any number of passes recorded into one pooled command buffer with the
//! barriers between them, submitted once; its completion is a timeline value ([`Submission`]).

use std::ffi::CString;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use ash::vk;

use super::memory::color_range;
use super::pipeline::MAX_BINDINGS_PER_KIND;
use super::release::{Garbage, Recorder};
use super::ring::RingKind;
use super::{
    vk_err, BindingKind, Buffer, BufferSlice, ComputePipeline, GpuContext, GpuError, Image,
    MemLocation, Profiler, TexelBuffer, WordTexels,
};

/// Transfers up to this size go through a staging ring; larger ones (or ones that find the ring
/// full) get a dedicated staging buffer, released after their submission.
pub(crate) const RING_MAX_TRANSFER: u64 = 1 << 20;
/// Descriptor sets in a recorder's first descriptor pool; each further pool doubles.
const FIRST_DESCRIPTOR_POOL: u32 = 64;

/// A resource given to a dispatch for one binding of its pipeline's set 0 (in binding order,
/// matching [`ComputePipeline::bindings`]).
#[derive(Clone, Copy, Debug)]
pub enum Bound<'a> {
    /// For [`BindingKind::StorageImage`].
    Image(&'a Image),
    /// For [`BindingKind::TexelBuffer`].
    Texels(&'a TexelBuffer),
    /// For [`BindingKind::TexelBuffer`]: a word view of a buffer.
    Words(&'a WordTexels),
}

impl Bound<'_> {
    /// The binding kind this resource fills.
    pub fn kind(&self) -> BindingKind {
        match self {
            Bound::Image(_) => BindingKind::StorageImage,
            Bound::Texels(_) | Bound::Words(_) => BindingKind::TexelBuffer,
        }
    }
}

/// Lifecycle value of a recorder still recording.
const RECORDING: u64 = 0;
/// Lifecycle value of a recorder dropped without a submission.
const ABANDONED: u64 = u64::MAX;

/// Where a [`Commands`] is in its life; shared with the [`super::Profiler`] and with
/// [`Readback`]s, which need its submission's timeline value (or to know that it never ran).
#[derive(Debug, Default)]
pub(crate) struct Lifecycle {
    /// [`RECORDING`], [`ABANDONED`] or the submission's timeline value.
    state: AtomicU64,
    /// Staging of readbacks dropped while the recorder still records: released with it.
    orphans: Mutex<Vec<Staging>>,
}

/// States of a [`Lifecycle`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum CommandsState {
    /// Being recorded.
    Recording,
    /// Submitted; the GPU finishes it at this timeline value.
    Submitted(u64),
    /// Dropped without a submission: nothing it recorded ran (or will be read).
    Abandoned,
}

impl Lifecycle {
    /// The current state.
    pub(crate) fn get(&self) -> CommandsState {
        match self.state.load(Ordering::Acquire) {
            RECORDING => CommandsState::Recording,
            ABANDONED => CommandsState::Abandoned,
            v => CommandsState::Submitted(v),
        }
    }

    /// Sets the final state and releases the orphaned staging accordingly.
    fn finish(&self, ctx: &GpuContext, state: u64) {
        let orphans = {
            let mut o = self.orphans.lock().unwrap_or_else(|p| p.into_inner());
            self.state.store(state, Ordering::Release);
            std::mem::take(&mut *o)
        };
        for staging in orphans {
            staging.release(ctx, state);
        }
    }
}

/// Host-visible memory a readback lands in.
#[derive(Debug)]
enum Staging {
    /// A region of the readback ring: (id, offset).
    Ring(u64, u64),
    /// A dedicated buffer.
    Buffer(Buffer),
}

impl Staging {
    /// Releases the staging once the submission with lifecycle value `state` is done with it.
    fn release(self, ctx: &GpuContext, state: u64) {
        match self {
            Staging::Ring(id, _) => {
                let value = if state == ABANDONED { 0 } else { state };
                ctx.defer_until(value, Garbage::RingRegion(RingKind::Readback, id));
            }
            // A buffer's drop defers it to the last submission, which is at least `state`.
            Staging::Buffer(b) => drop(b),
        }
    }
}

/// A command recorder: passes recorded into one command buffer, submitted once.
///
/// Resources passed by reference must outlive it (`'a`); buffers reached only through device
/// addresses must be kept alive by the caller until [`Commands::submit_async`] returns (after
/// that, dropping them is safe: their release waits for the submission). Dropping it unsubmitted
/// runs nothing.
///
/// Thread safety: a command pool must be externally synchronised while any of its buffers is
/// recorded. Each `Commands` takes a whole pooled recorder (command pool + command buffer +
/// descriptor pools) from the context's free list for itself, so recorders on different threads
/// need no lock; the recorder goes back to the list, reset, once its submission has completed.
/// Only the submit itself locks the queue.
pub struct Commands<'a> {
    pub(crate) raw: vk::CommandBuffer,
    recorder: Option<Recorder>,
    name: String,
    /// Upload-ring regions this recording copies from.
    upload_regions: Vec<u64>,
    /// Dedicated staging buffers this recording copies from (released after the submission).
    staging: Vec<Buffer>,
    /// Shared with the profiler's passes and the readbacks recorded here.
    pub(crate) lifecycle: Arc<Lifecycle>,
    pub(crate) ctx: Arc<GpuContext>,
    /// The buffer ranges the transfers since the last full barrier read and write, when
    /// nothing else was recorded since it: a transfer that conflicts with none of them joins
    /// them without a barrier between (docs/gpu.md, "Barriers").
    transfers: Vec<TransferAccess>,
    /// Whether a command other than a transfer was recorded since the last full barrier.
    commands_since_barrier: bool,
    /// Full barriers recorded so far.
    barriers: u32,
    _resources: PhantomData<&'a ()>,
}

/// A byte range of a buffer that a recorded transfer reads or writes.
#[derive(Clone, Copy, Debug)]
struct TransferAccess {
    buffer: vk::Buffer,
    start: u64,
    end: u64,
    write: bool,
}

impl TransferAccess {
    /// Whether the two accesses must be ordered: the same bytes, at least one written.
    fn conflicts(&self, other: &TransferAccess) -> bool {
        self.buffer == other.buffer
            && self.start < other.end
            && other.start < self.end
            && (self.write || other.write)
    }
}

impl std::fmt::Debug for Commands<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Commands")
            .field("name", &self.name)
            .finish()
    }
}

/// A submitted recording: completes when the queue's timeline semaphore reaches `value`.
#[derive(Clone, Debug)]
pub struct Submission {
    value: u64,
    ctx: Arc<GpuContext>,
}

impl Submission {
    /// The timeline value the submission signals.
    pub fn value(&self) -> u64 {
        self.value
    }

    /// Whether the GPU has finished it (does not block).
    pub fn is_done(&self) -> Result<bool, GpuError> {
        Ok(self.ctx.completed_value()? >= self.value)
    }

    /// Blocks until the GPU has finished it.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.ctx.wait_for(self.value)
    }
}

/// Data a recording copies into host-visible staging (a readback-ring region, or a dedicated
/// buffer when large); [`Readback::read`] returns it once the submission has completed.
#[derive(Debug)]
pub struct Readback<T: bytemuck::Pod> {
    staging: Option<Staging>,
    count: usize,
    lifecycle: Arc<Lifecycle>,
    ctx: Arc<GpuContext>,
    _t: PhantomData<T>,
}

impl<T: bytemuck::Pod> Readback<T> {
    /// Waits for the submission (if it has not completed yet) and returns the data. Errors if
    /// the recorder was not submitted, or was dropped without a submission.
    pub fn read(mut self) -> Result<Vec<T>, GpuError> {
        let value = match self.lifecycle.get() {
            CommandsState::Submitted(v) => v,
            CommandsState::Recording => {
                return Err(GpuError::InvalidArgument(
                    "Readback::read before its commands were submitted".into(),
                ))
            }
            CommandsState::Abandoned => {
                return Err(GpuError::InvalidArgument(
                    "Readback::read of commands dropped unsubmitted".into(),
                ))
            }
        };
        self.ctx.wait_for(value)?;
        let mut out = vec![T::zeroed(); self.count];
        let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        match &self.staging {
            Some(Staging::Ring(_, offset)) => {
                let ring = self.ctx.readback_ring();
                let p = ring.ptr(*offset);
                if p.is_null() {
                    return Err(GpuError::InvalidArgument(
                        "readback ring is not mapped".into(),
                    ));
                }
                // SAFETY: the region [offset, offset + len) belongs to this readback, the ring
                // is persistently mapped and coherent, and the GPU finished writing it.
                unsafe { std::ptr::copy_nonoverlapping(p, bytes.as_mut_ptr(), bytes.len()) };
            }
            Some(Staging::Buffer(b)) => {
                let m = b.mapped().ok_or_else(|| {
                    GpuError::InvalidArgument("staging buffer is not mapped".into())
                })?;
                bytes.copy_from_slice(&m[..bytes.len()]);
            }
            None => {}
        }
        if let Some(s) = self.staging.take() {
            s.release(&self.ctx, value);
        }
        Ok(out)
    }
}

impl<T: bytemuck::Pod> Drop for Readback<T> {
    fn drop(&mut self) {
        let Some(staging) = self.staging.take() else {
            return;
        };
        let mut orphans = self
            .lifecycle
            .orphans
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        match self.lifecycle.state.load(Ordering::Acquire) {
            // The copy may still be submitted: release with the recorder.
            RECORDING => orphans.push(staging),
            state => {
                drop(orphans);
                staging.release(&self.ctx, state);
            }
        }
    }
}

impl GpuContext {
    /// Starts recording a named command buffer (any thread may record its own at once). Also
    /// releases garbage whose submission has completed.
    pub fn begin_commands<'a>(self: &Arc<Self>, name: &str) -> Result<Commands<'a>, GpuError> {
        self.maintain();
        let recorder = self.acquire_recorder()?;
        let mut cmd = Commands {
            raw: recorder.buffer,
            recorder: Some(recorder),
            name: name.to_string(),
            upload_regions: Vec::new(),
            staging: Vec::new(),
            lifecycle: Arc::new(Lifecycle::default()),
            ctx: Arc::clone(self),
            transfers: Vec::new(),
            commands_since_barrier: true,
            barriers: 0,
            _resources: PhantomData,
        };
        // SAFETY: the recorder is reset and owned by `cmd` alone (see the type's docs).
        unsafe {
            self.device
                .begin_command_buffer(
                    cmd.raw,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .map_err(vk_err("vkBeginCommandBuffer"))?;
        }
        if let Some(r) = &cmd.recorder {
            self.set_name(r.pool, &format!("{name} (pool)"));
        }
        self.set_name(cmd.raw, name);
        // Earlier submissions' writes become visible to this one (same queue, submission order).
        cmd.barrier();
        Ok(cmd)
    }
}

impl<'a> Commands<'a> {
    /// Name given at [`GpuContext::begin_commands`].
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Records a compute dispatch of `groups` workgroups with the given push-constant bytes and
    /// the resources of the pipeline's set 0 (`bound[i]` at binding i; empty when it has none).
    /// Like buffers reached through device addresses, the bound resources must stay alive until
    /// the submission has completed.
    pub fn dispatch(
        &mut self,
        pipeline: &'a ComputePipeline,
        groups: [u32; 3],
        push_constants: &[u8],
        bound: &[Bound<'_>],
    ) -> Result<(), GpuError> {
        let max = self.ctx.info().max_compute_workgroup_count;
        if groups.iter().zip(max).any(|(&g, m)| g > m) {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{}': {groups:?} workgroups exceed the device limit {max:?}",
                pipeline.name()
            )));
        }
        self.bind(pipeline, push_constants, bound)?;
        if groups.iter().all(|&g| g > 0) {
            self.ctx.note_dispatch(pipeline);
            // SAFETY: recording into our command buffer; the pipeline is bound.
            unsafe {
                (self.ctx.device).cmd_dispatch(self.raw, groups[0], groups[1], groups[2]);
            }
        }
        Ok(())
    }

    /// Records a dispatch of zero workgroups of `pipeline` (push constants zero, `bound` as
    /// [`Commands::dispatch`] takes it): it runs nothing, but a driver that compiles a
    /// pipeline's native code at its first dispatch rather than at its creation (lavapipe's
    /// llvmpipe) compiles it here, so that work whose first pass must not stall can make its
    /// pipelines ready ahead (`GpuHashDag::prepare_tools`, [`GpuContext::first_dispatches`]).
    pub fn warm(
        &mut self,
        pipeline: &'a ComputePipeline,
        bound: &[Bound<'_>],
    ) -> Result<(), GpuError> {
        let zeros = vec![0u8; pipeline.push_constant_size as usize];
        self.bind(pipeline, &zeros, bound)?;
        self.ctx.note_dispatch(pipeline);
        // SAFETY: recording into our command buffer; the pipeline is bound. Zero workgroups
        // are a valid dispatch that runs no invocation.
        unsafe { (self.ctx.device).cmd_dispatch(self.raw, 0, 0, 0) };
        Ok(())
    }

    /// Binds `pipeline`, its descriptor set (`bound`) and push constants (all checked) for the
    /// dispatch that follows.
    fn bind(
        &mut self,
        pipeline: &'a ComputePipeline,
        push_constants: &[u8],
        bound: &[Bound<'_>],
    ) -> Result<(), GpuError> {
        if push_constants.len() as u32 != pipeline.push_constant_size {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{}' expects {} push-constant bytes, got {}",
                pipeline.name(),
                pipeline.push_constant_size,
                push_constants.len()
            )));
        }
        if !bound
            .iter()
            .map(Bound::kind)
            .eq(pipeline.bindings().iter().copied())
        {
            let kinds: Vec<BindingKind> = bound.iter().map(Bound::kind).collect();
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{}' binds {:?}, the dispatch gives {kinds:?}",
                pipeline.name(),
                pipeline.bindings()
            )));
        }
        let set = match pipeline.set_layout {
            Some(layout) => Some(self.descriptor_set(layout, bound)?),
            None => None,
        };
        self.before_command();
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
        }
        Ok(())
    }

    /// Records an indirect compute dispatch: the workgroup counts are the three `u32`s at byte
    /// `offset` of `args`, written by earlier passes (e.g. `voxdag::compute`'s indirect
    /// arguments), so a pass can be sized on the GPU. The counts must not exceed the device's
    /// `maxComputeWorkGroupCount` (the GPU cannot check this; a zero count dispatches nothing).
    /// Records its own barrier making earlier compute/transfer writes visible to the
    /// indirect-argument read.
    pub fn dispatch_indirect(
        &mut self,
        pipeline: &'a ComputePipeline,
        args: &'a Buffer,
        offset: u64,
        push_constants: &[u8],
        bound: &[Bound<'_>],
    ) -> Result<(), GpuError> {
        if !offset.is_multiple_of(4) || offset.checked_add(12).is_none_or(|end| end > args.size()) {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{}': indirect arguments at byte {offset} of '{}' ({} bytes) must be \
                 4-byte aligned and hold three u32s",
                pipeline.name(),
                args.name(),
                args.size()
            )));
        }
        self.bind(pipeline, push_constants, bound)?;
        self.ctx.note_dispatch(pipeline);
        let barrier = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::INDIRECT_COMMAND_READ);
        // SAFETY: recording into our command buffer; `args` has INDIRECT_BUFFER usage and the
        // range was checked above.
        unsafe {
            self.ctx.device.cmd_pipeline_barrier(
                self.raw,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::DRAW_INDIRECT,
                vk::DependencyFlags::empty(),
                &[barrier],
                &[],
                &[],
            );
            self.ctx
                .device
                .cmd_dispatch_indirect(self.raw, args.raw, offset);
        }
        Ok(())
    }

    /// Allocates and writes a descriptor set binding `bound` (binding i = `bound[i]`), from the
    /// recorder's descriptor pools (a new pool, twice the previous, when they are full: no
    /// fixed cap per recording).
    fn descriptor_set(
        &mut self,
        layout: vk::DescriptorSetLayout,
        bound: &[Bound<'_>],
    ) -> Result<vk::DescriptorSet, GpuError> {
        let device = &self.ctx.device;
        let recorder = self
            .recorder
            .as_mut()
            .ok_or_else(|| GpuError::InvalidArgument("recording after submit".into()))?;
        let layouts = [layout];
        // SAFETY: the pools belong to this recorder alone and are reset only after its
        // submission completed.
        unsafe {
            let set = loop {
                let capacity = |i: usize| FIRST_DESCRIPTOR_POOL << i.min(10);
                if recorder.current_pool < recorder.descriptor_pools.len()
                    && recorder.current_sets >= capacity(recorder.current_pool)
                {
                    recorder.current_pool += 1;
                    recorder.current_sets = 0;
                }
                if recorder.current_pool == recorder.descriptor_pools.len() {
                    // Room for every set to hold the most descriptors of each kind a pipeline may bind.
                    let sets = capacity(recorder.descriptor_pools.len());
                    let sizes = BindingKind::ALL.map(|k| vk::DescriptorPoolSize {
                        ty: k.descriptor_type(),
                        descriptor_count: sets * MAX_BINDINGS_PER_KIND,
                    });
                    let pool = device
                        .create_descriptor_pool(
                            &vk::DescriptorPoolCreateInfo::default()
                                .max_sets(sets)
                                .pool_sizes(&sizes),
                            None,
                        )
                        .map_err(vk_err("vkCreateDescriptorPool"))?;
                    self.ctx
                        .set_name(pool, &format!("{} (descriptors)", self.name));
                    recorder.descriptor_pools.push(pool);
                }
                let pool = recorder.descriptor_pools[recorder.current_pool];
                match device.allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default()
                        .descriptor_pool(pool)
                        .set_layouts(&layouts),
                ) {
                    Ok(sets) => {
                        recorder.current_sets += 1;
                        break sets[0];
                    }
                    Err(vk::Result::ERROR_OUT_OF_POOL_MEMORY)
                    | Err(vk::Result::ERROR_FRAGMENTED_POOL) => {
                        recorder.current_pool += 1;
                        recorder.current_sets = 0;
                    }
                    Err(e) => return Err(vk_err("vkAllocateDescriptorSets")(e)),
                }
            };
            let image_infos: Vec<[vk::DescriptorImageInfo; 1]> = bound
                .iter()
                .map(|b| match b {
                    Bound::Image(image) => [vk::DescriptorImageInfo {
                        sampler: vk::Sampler::null(),
                        image_view: image.view,
                        image_layout: vk::ImageLayout::GENERAL,
                    }],
                    Bound::Texels(_) | Bound::Words(_) => [vk::DescriptorImageInfo::default()],
                })
                .collect();
            let writes: Vec<vk::WriteDescriptorSet> = bound
                .iter()
                .enumerate()
                .map(|(i, b)| {
                    let write = vk::WriteDescriptorSet::default()
                        .dst_set(set)
                        .dst_binding(i as u32)
                        .descriptor_type(b.kind().descriptor_type());
                    match b {
                        Bound::Image(_) => write.image_info(&image_infos[i]),
                        Bound::Texels(t) => write.texel_buffer_view(std::slice::from_ref(&t.view)),
                        Bound::Words(t) => write.texel_buffer_view(std::slice::from_ref(&t.view)),
                    }
                })
                .collect();
            device.update_descriptor_sets(&writes, &[]);
            Ok(set)
        }
    }

    /// Descriptor pools this recorder has (grown on demand; for tests of the growth).
    pub fn descriptor_pool_count(&self) -> usize {
        self.recorder
            .as_ref()
            .map_or(0, |r| r.descriptor_pools.len())
    }

    /// Full memory barrier: compute and transfer writes become visible to later compute,
    /// transfer and host accesses. Left out where nothing was recorded since the last one.
    pub fn barrier(&mut self) {
        if self.transfers.is_empty() && !self.commands_since_barrier {
            return;
        }
        self.transfers.clear();
        self.commands_since_barrier = false;
        self.barriers += 1;
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

    /// Full barriers recorded so far, the one every recording starts with included (what
    /// [`Commands::barrier`] left out is not counted).
    pub fn barriers_recorded(&self) -> u32 {
        self.barriers
    }

    /// Called before recording a command other than a transfer (also by code that records on
    /// [`Commands::raw`] directly: the profiler, the swapchain): the transfers recorded since
    /// the last barrier complete before it.
    pub(crate) fn before_command(&mut self) {
        if !self.transfers.is_empty() {
            self.barrier();
        }
        self.commands_since_barrier = true;
    }

    /// Called before recording a transfer with these accesses: a barrier first when a command
    /// other than a transfer, or a transfer touching the same bytes (one of them writing), was
    /// recorded since the last one. Transfers are thus ordered exactly as with a barrier before
    /// and after each, while independent ones (uploads and fills of distinct buffers) share one.
    fn before_transfer(&mut self, accesses: &[TransferAccess]) {
        let conflict = accesses
            .iter()
            .any(|a| self.transfers.iter().any(|t| t.conflicts(a)));
        if self.commands_since_barrier || conflict {
            self.barrier();
        }
        self.transfers.extend_from_slice(accesses);
    }

    /// Copies `size` bytes between buffers, ordered against every other command like a copy
    /// between barriers (docs/gpu.md, "Barriers").
    pub fn copy_buffer(
        &mut self,
        src: &'a Buffer,
        src_offset: u64,
        dst: &'a Buffer,
        dst_offset: u64,
        size: u64,
    ) -> Result<(), GpuError> {
        for (b, off) in [(src, src_offset), (dst, dst_offset)] {
            if off.checked_add(size).is_none_or(|e| e > b.size()) {
                return Err(GpuError::OutOfRange {
                    name: b.name().to_string(),
                    offset: off,
                    len: size,
                    size: b.size(),
                });
            }
        }
        self.copy_raw(src.raw, src_offset, dst.raw, dst_offset, size);
        Ok(())
    }

    /// Records a copy between raw buffers, ordered against every other command like one between
    /// barriers ([`Commands::before_transfer`]; ranges checked by the caller).
    fn copy_raw(
        &mut self,
        src: vk::Buffer,
        src_offset: u64,
        dst: vk::Buffer,
        dst_offset: u64,
        size: u64,
    ) {
        self.before_transfer(&[
            TransferAccess {
                buffer: src,
                start: src_offset,
                end: src_offset + size,
                write: false,
            },
            TransferAccess {
                buffer: dst,
                start: dst_offset,
                end: dst_offset + size,
                write: true,
            },
        ]);
        let region = vk::BufferCopy {
            src_offset,
            dst_offset,
            size,
        };
        // SAFETY: ranges checked by the caller; every buffer has TRANSFER usage.
        unsafe {
            self.ctx
                .device
                .cmd_copy_buffer(self.raw, src, dst, &[region]);
        }
    }

    /// Records an upload of `data` to byte `offset` of `dst`: the bytes are staged now (in the
    /// upload ring when small and there is room, else in a dedicated staging buffer) and copied
    /// when the recording runs.
    pub fn upload<T: bytemuck::Pod>(
        &mut self,
        dst: &'a Buffer,
        offset: u64,
        data: &[T],
    ) -> Result<(), GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let len = bytes.len() as u64;
        dst.check_range(offset, len)?;
        if len == 0 {
            return Ok(());
        }
        if len <= RING_MAX_TRANSFER {
            let mut ring = self.ctx.upload_ring();
            if let Some((id, at)) = ring.alloc.alloc(len) {
                let p = ring.ptr(at);
                if !p.is_null() {
                    // SAFETY: the region [at, at + len) was just reserved for this upload and the
                    // ring is persistently mapped.
                    unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), p, bytes.len()) };
                    let raw = ring.raw;
                    drop(ring);
                    self.upload_regions.push(id);
                    self.copy_raw(raw, at, dst.raw, offset, len);
                    return Ok(());
                }
                ring.alloc.free(id);
            }
        }
        let mut staging = self.ctx.create_buffer(
            &format!("{} (upload staging)", dst.name()),
            len,
            MemLocation::CpuToGpu,
        )?;
        staging
            .mapped_mut()
            .ok_or_else(|| GpuError::InvalidArgument("staging buffer is not mapped".into()))?
            [..bytes.len()]
            .copy_from_slice(bytes);
        self.copy_raw(staging.raw, 0, dst.raw, offset, len);
        self.staging.push(staging);
        Ok(())
    }

    /// Records a copy of `count` `T`s at byte `offset` of `src` into host-visible staging (the
    /// readback ring when small and there is room); read them with [`Readback::read`] after the
    /// submission.
    pub fn readback<T: bytemuck::Pod>(
        &mut self,
        src: &'a Buffer,
        offset: u64,
        count: usize,
    ) -> Result<Readback<T>, GpuError> {
        let len = (count as u64)
            .checked_mul(std::mem::size_of::<T>() as u64)
            .ok_or_else(|| GpuError::InvalidArgument("read size overflows".into()))?;
        src.check_range(offset, len)?;
        let mut staging = None;
        if len == 0 {
            // Nothing to copy.
        } else if len <= RING_MAX_TRANSFER {
            let mut ring = self.ctx.readback_ring();
            if let Some((id, at)) = ring.alloc.alloc(len) {
                let raw = ring.raw;
                drop(ring);
                self.copy_raw(src.raw, offset, raw, at, len);
                staging = Some(Staging::Ring(id, at));
            }
        }
        if staging.is_none() && len > 0 {
            let buffer = self.ctx.create_buffer(
                &format!("{} (readback staging)", src.name()),
                len,
                MemLocation::GpuToCpu,
            )?;
            self.copy_raw(src.raw, offset, buffer.raw, 0, len);
            staging = Some(Staging::Buffer(buffer));
        }
        Ok(Readback {
            staging,
            count,
            lifecycle: Arc::clone(&self.lifecycle),
            ctx: Arc::clone(&self.ctx),
            _t: PhantomData,
        })
    }

    /// Fills a whole buffer with a repeated `u32` (size rounded down to 4 bytes).
    pub fn fill_buffer(&mut self, dst: &'a Buffer, value: u32) {
        // The buffer's own size, not the Vulkan buffer's (a reused size class may be larger).
        self.fill_raw(dst, 0, dst.size() & !3, value);
    }

    /// Fills bytes `[offset, offset + len)` of a buffer with a repeated `u32` (both multiples of
    /// 4 bytes, inside the buffer).
    pub fn fill_range(
        &mut self,
        dst: &'a Buffer,
        offset: u64,
        len: u64,
        value: u32,
    ) -> Result<(), GpuError> {
        dst.check_range(offset, len)?;
        if !offset.is_multiple_of(4) || !len.is_multiple_of(4) {
            return Err(GpuError::InvalidArgument(format!(
                "fill of '{}' at {offset}+{len}: not a multiple of 4 bytes",
                dst.name()
            )));
        }
        self.fill_raw(dst, offset, len, value);
        Ok(())
    }

    /// Fills a buffer range with a repeated `u32` (its offset a multiple of 4 bytes, its size
    /// rounded down to one).
    pub fn fill_slice(&mut self, dst: BufferSlice<'a>, value: u32) -> Result<(), GpuError> {
        self.fill_range(dst.buffer(), dst.offset(), dst.size() & !3, value)
    }

    /// `vkCmdFillBuffer` of a checked range, ordered like one between barriers.
    fn fill_raw(&mut self, dst: &'a Buffer, offset: u64, len: u64, value: u32) {
        if len > 0 {
            self.before_transfer(&[TransferAccess {
                buffer: dst.raw,
                start: offset,
                end: offset + len,
                write: true,
            }]);
            // SAFETY: an in-range fill (a multiple of 4 bytes) of a TRANSFER_DST buffer.
            unsafe {
                self.ctx
                    .device
                    .cmd_fill_buffer(self.raw, dst.raw, offset, len, value);
            }
        }
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
        self.before_command();
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
        self.before_command();
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

    /// Opens a pass of a pass-recording API that takes an optional profiler: a profiled pass
    /// (debug label + timestamps) with one, a plain debug label without.
    pub fn begin_pass(&mut self, profiler: &mut Option<&mut Profiler>, name: &str) {
        match profiler {
            Some(p) => p.begin_pass(self, name),
            None => self.begin_label(name),
        }
    }

    /// Closes what [`Commands::begin_pass`] opened (pass the same profiler).
    pub fn end_pass(&mut self, profiler: &mut Option<&mut Profiler>) {
        match profiler {
            Some(p) => p.end_pass(self),
            None => self.end_label(),
        }
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

    /// Ends recording, submits, and waits for the GPU to finish (all writes visible to the
    /// host): [`Commands::submit_async`] + [`Submission::wait`].
    pub fn submit(self) -> Result<(), GpuError> {
        self.submit_async()?.wait()
    }

    /// Ends recording and submits without waiting; returns the submission (its timeline value).
    /// The recorder's command buffer, command pool and descriptor pools are reused once the GPU
    /// has passed that value.
    pub fn submit_async(self) -> Result<Submission, GpuError> {
        self.submit_async_with(&[], &[])
    }

    /// [`Commands::submit_async`] that also waits for binary semaphores (each at its stage) and
    /// signals binary semaphores (for the swapchain: image acquired / ready to present).
    pub(crate) fn submit_async_with(
        mut self,
        waits: &[(vk::Semaphore, vk::PipelineStageFlags)],
        signals: &[vk::Semaphore],
    ) -> Result<Submission, GpuError> {
        let device = &self.ctx.device;
        let host_barrier = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        // SAFETY: the command buffer is ours; the queue is locked while submitting; everything
        // it uses stays alive until the timeline passes its value (deferred release).
        let value = unsafe {
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
            let wait_semaphores: Vec<vk::Semaphore> = waits.iter().map(|w| w.0).collect();
            let wait_stages: Vec<vk::PipelineStageFlags> = waits.iter().map(|w| w.1).collect();
            let wait_values = vec![0u64; waits.len()];
            let mut signal_semaphores: Vec<vk::Semaphore> = signals.to_vec();
            signal_semaphores.push(self.ctx.timeline());
            let buffers = [self.raw];
            self.ctx.submit_next(|queue, value| {
                let mut signal_values = vec![0u64; signals.len()];
                signal_values.push(value);
                let mut timeline = vk::TimelineSemaphoreSubmitInfo::default()
                    .wait_semaphore_values(&wait_values)
                    .signal_semaphore_values(&signal_values);
                let submit = vk::SubmitInfo::default()
                    .wait_semaphores(&wait_semaphores)
                    .wait_dst_stage_mask(&wait_stages)
                    .command_buffers(&buffers)
                    .signal_semaphores(&signal_semaphores)
                    .push_next(&mut timeline);
                device
                    .queue_submit(queue, &[submit], vk::Fence::null())
                    .map_err(vk_err("vkQueueSubmit"))
            })?
        };
        self.lifecycle.finish(&self.ctx, value);
        if let Some(r) = self.recorder.take() {
            self.ctx.defer_until(value, Garbage::Recorder(r));
        }
        for id in self.upload_regions.drain(..) {
            self.ctx
                .defer_until(value, Garbage::RingRegion(RingKind::Upload, id));
        }
        // Dedicated staging buffers drop with `self`, deferred to this (the last) submission.
        self.ctx.maintain();
        Ok(Submission {
            value,
            ctx: Arc::clone(&self.ctx),
        })
    }
}

impl Drop for Commands<'_> {
    fn drop(&mut self) {
        if self.lifecycle.get() == CommandsState::Recording {
            self.lifecycle.finish(&self.ctx, ABANDONED);
        }
        // Never submitted (or the submit failed): nothing of it is in flight.
        if let Some(r) = self.recorder.take() {
            self.ctx.recycle(r);
        }
        for id in self.upload_regions.drain(..) {
            self.ctx
                .defer_until(0, Garbage::RingRegion(RingKind::Upload, id));
        }
    }
}
