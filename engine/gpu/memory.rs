//! Buffers (with device addresses), storage images, uploads and readbacks.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::release::{Garbage, Recyclable};
use super::{vk_err, GpuContext, GpuError};

/// Largest staging buffer used by uploads and readbacks; bigger transfers go in chunks.
const STAGING_CHUNK: u64 = 64 << 20;

/// Where a buffer's memory lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemLocation {
    /// Device-local; filled by uploads and shaders, read back through a staging buffer.
    GpuOnly,
    /// Host-visible, mapped, written by the CPU (staging, small parameter blocks).
    CpuToGpu,
    /// Host-visible, mapped, cached for CPU reads (readback).
    GpuToCpu,
}

impl MemLocation {
    fn to_allocator(self) -> MemoryLocation {
        match self {
            MemLocation::GpuOnly => MemoryLocation::GpuOnly,
            MemLocation::CpuToGpu => MemoryLocation::CpuToGpu,
            MemLocation::GpuToCpu => MemoryLocation::GpuToCpu,
        }
    }
}

/// A named storage buffer with a device address; usable as storage, transfer source and
/// destination, and indirect-dispatch arguments.
///
/// Shaders reach it through its device address (`GL_EXT_buffer_reference`), so it may exceed
/// `maxStorageBufferRange`. Dropping it queues it for release once the last submission so far
/// has completed (deferred release), so it may be dropped right after the submission that uses
/// it returned.
pub struct Buffer {
    pub(crate) raw: vk::Buffer,
    allocation: Option<Allocation>,
    size: u64,
    /// Bytes of the Vulkan buffer: `size`, rounded up to the size class, plus the slack of
    /// [`texel_view_slack`].
    capacity: u64,
    address: u64,
    name: String,
    location: MemLocation,
    /// The reusable size class of the Vulkan buffer (at least `size`), `None` for buffers
    /// larger than [`RECYCLE_MAX_BYTES`], which are destroyed when dropped.
    class: Option<u64>,
    ctx: Arc<GpuContext>,
}

/// Buffers up to this size are created in power-of-two size classes and kept for reuse when
/// dropped: creating and destroying a Vulkan buffer with its allocation costs far more than the
/// small passes of an edit that use it (docs/gpu.md, "Buffer reuse").
pub(crate) const RECYCLE_MAX_BYTES: u64 = 4 << 20;

/// Smallest size class.
const RECYCLE_MIN_BYTES: u64 = 256;

/// The size class of a `size`-byte buffer, `None` when it is too large to be reused.
pub(crate) fn size_class(size: u64) -> Option<u64> {
    (size <= RECYCLE_MAX_BYTES).then(|| size.next_power_of_two().max(RECYCLE_MIN_BYTES))
}

/// Slack after a buffer's `base` bytes (its size class, or its size when it has none) in the
/// Vulkan buffer: at least [`TEXEL_VIEW_SLACK`] (room for [`texel_view_range`]) and such that
/// the Vulkan buffer's size is never a power of two. llvmpipe (lavapipe) compiles a pipeline's
/// native code per combination of its bound texel views' static state, which includes whether
/// the buffer's size is a power of two and whether bits 8-15 of the view's byte range are all
/// zero (`lp_sampler_static_texture_state` reads them as the view's last mip level), so views
/// of buffers of varying sizes made the edit's `build_items` compile anew (~0.1 s each) in
/// the middle of loads and first edits (docs/gpu.md, "One native variant per texel binding").
fn texel_view_slack(base: u64) -> u64 {
    if (base + TEXEL_VIEW_SLACK).is_power_of_two() {
        2 * TEXEL_VIEW_SLACK
    } else {
        TEXEL_VIEW_SLACK
    }
}

/// Bytes a texel view may reach past the buffer's own size ([`texel_view_range`]).
const TEXEL_VIEW_SLACK: u64 = 256;

/// The byte range of a texel view of a buffer's first `bytes` bytes: `bytes`, or with bit 8
/// set where its bits 8-15 are all zero (see [`texel_view_slack`]), so every view has the
/// same static state on llvmpipe.
fn texel_view_range(bytes: u64) -> u64 {
    if (bytes >> 8) & 0xff == 0 {
        bytes | 0x100
    } else {
        bytes
    }
}

impl std::fmt::Debug for Buffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Buffer")
            .field("name", &self.name)
            .field("size", &self.size)
            .field("address", &format_args!("{:#x}", self.address))
            .field("location", &self.location)
            .finish()
    }
}

impl Buffer {
    /// Size in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// GPU virtual address of byte 0, for `GL_EXT_buffer_reference` (push constants or buffers).
    pub fn address(&self) -> u64 {
        self.address
    }

    /// Debug name (also the allocation's name).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Memory location the buffer was created with.
    pub fn location(&self) -> MemLocation {
        self.location
    }

    pub(crate) fn check_range(&self, offset: u64, len: u64) -> Result<(), GpuError> {
        if offset.checked_add(len).is_none_or(|end| end > self.size) {
            return Err(GpuError::OutOfRange {
                name: self.name.clone(),
                offset,
                len,
                size: self.size,
            });
        }
        Ok(())
    }

    /// Mapped bytes of a host-visible buffer (its `size` bytes; the size class may hold more).
    pub(crate) fn mapped(&self) -> Option<&[u8]> {
        let size = self.size as usize;
        self.allocation
            .as_ref()
            .and_then(|a| a.mapped_slice())
            .map(|m| &m[..size])
    }

    pub(crate) fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        let size = self.size as usize;
        self.allocation
            .as_mut()
            .and_then(|a| a.mapped_slice_mut())
            .map(|m| &mut m[..size])
    }
}

/// A byte range of a buffer: where a pass reads or writes part of a larger buffer (several
/// per-size regions of one allocation, for instance). Passes see it as a device address.
#[derive(Clone, Copy, Debug)]
pub struct BufferSlice<'a> {
    buffer: &'a Buffer,
    offset: u64,
    size: u64,
}

impl<'a> BufferSlice<'a> {
    /// The buffer the range is in.
    pub fn buffer(&self) -> &'a Buffer {
        self.buffer
    }

    /// Byte offset of the range in its buffer.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// Size of the range in bytes.
    pub fn size(&self) -> u64 {
        self.size
    }

    /// GPU virtual address of the range's first byte.
    pub fn address(&self) -> u64 {
        self.buffer.address + self.offset
    }

    /// Debug name of the buffer.
    pub fn name(&self) -> &'a str {
        &self.buffer.name
    }
}

impl<'a> From<&'a Buffer> for BufferSlice<'a> {
    fn from(buffer: &'a Buffer) -> Self {
        BufferSlice {
            buffer,
            offset: 0,
            size: buffer.size,
        }
    }
}

impl Buffer {
    /// Bytes `[offset, offset + size)` of the buffer, checked against its size.
    pub fn slice(&self, offset: u64, size: u64) -> Result<BufferSlice<'_>, GpuError> {
        self.check_range(offset, size)?;
        Ok(BufferSlice {
            buffer: self,
            offset,
            size,
        })
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        if let Some(a) = self.allocation.take() {
            let recyclable = self.class.map(|class| Recyclable {
                class,
                location: self.location,
                address: self.address,
            });
            self.ctx.defer(Garbage::Buffer(self.raw, a, recyclable));
        }
    }
}

/// Read-only pairs of 32-bit words that shaders read with `texelFetch` on a `usamplerBuffer`
/// (an `R32G32_UINT` uniform texel buffer; [`super::pipeline::BindingKind::TexelBuffer`]).
///
/// For small tables read at per-invocation indices: lavapipe loads through a buffer address
/// one invocation at a time (a loop over the SIMD lanes with a branch each), but fetches texels
/// for all lanes at once (docs/pathtracing.md, "Format tables as texels").
pub struct TexelBuffer {
    pub(crate) view: vk::BufferView,
    buffer: Buffer,
    texels: u64,
}

impl std::fmt::Debug for TexelBuffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TexelBuffer")
            .field("buffer", &self.buffer)
            .field("texels", &self.texels)
            .finish()
    }
}

impl TexelBuffer {
    /// Number of texels (word pairs).
    pub fn texels(&self) -> u64 {
        self.texels
    }

    /// The buffer behind the view.
    pub fn buffer(&self) -> &Buffer {
        &self.buffer
    }
}

impl Drop for TexelBuffer {
    fn drop(&mut self) {
        // Queued before the buffer (dropped after this), so destroyed first.
        self.buffer.ctx.defer(Garbage::BufferView(self.view));
    }
}

/// A uniform texel view of a buffer's words, bound per dispatch ([`super::Bound::Words`]):
/// `R32_UINT`, one word a texel ([`GpuContext::word_texels`]), or `R32G32B32A32_UINT`, four
/// ([`GpuContext::record_texels`]). Passes read it with `texelFetch`, which lavapipe runs for
/// all SIMD lanes at once where a load through an address is a loop over them.
pub struct WordTexels {
    pub(crate) view: vk::BufferView,
    ctx: Arc<GpuContext>,
    texels: u64,
}

impl std::fmt::Debug for WordTexels {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WordTexels")
            .field("texels", &self.texels)
            .finish()
    }
}

impl WordTexels {
    /// Number of texels (words, or groups of four of a record view).
    pub fn texels(&self) -> u64 {
        self.texels
    }
}

impl Drop for WordTexels {
    fn drop(&mut self) {
        self.ctx.defer(Garbage::BufferView(self.view));
    }
}

impl GpuContext {
    /// A word view of all of `buffer` (at most `maxTexelBufferElements` words).
    pub fn word_texels(self: &Arc<Self>, buffer: &Buffer) -> Result<WordTexels, GpuError> {
        let texels = buffer.size / 4;
        self.check_texels(&format!("word view of '{}'", buffer.name), texels)?;
        Ok(WordTexels {
            view: self.texel_view(buffer, vk::Format::R32_UINT, texels)?,
            ctx: Arc::clone(self),
            texels,
        })
    }

    /// A view of all of `buffer` as `uvec4` texels (`R32G32B32A32_UINT`, at most
    /// `maxTexelBufferElements`): records of 16-byte multiples read whole (a shared struct's
    /// `NAME_FROM_UVEC4S`, docs/gpu.md "Records read as texels").
    pub fn record_texels(self: &Arc<Self>, buffer: &Buffer) -> Result<WordTexels, GpuError> {
        let texels = buffer.size / 16;
        self.check_texels(&format!("record view of '{}'", buffer.name), texels)?;
        Ok(WordTexels {
            view: self.texel_view(buffer, vk::Format::R32G32B32A32_UINT, texels)?,
            ctx: Arc::clone(self),
            texels,
        })
    }

    /// Errors unless a texel buffer view of `texels` texels fits the device (1 to
    /// `maxTexelBufferElements`); `what` names the view in the error.
    fn check_texels(&self, what: &str, texels: u64) -> Result<(), GpuError> {
        let max = self.info().max_texel_buffer_elements;
        if texels == 0 || texels > max as u64 {
            return Err(GpuError::InvalidArgument(format!(
                "{what}: {texels} texels, the device takes 1 to {max} (maxTexelBufferElements)"
            )));
        }
        Ok(())
    }

    /// A uniform texel buffer view of the first `texels` texels of `buffer` in `format` (a
    /// format whose uniform texel buffer support Vulkan requires: 4, 8 or 16 bytes a texel),
    /// named after the buffer. Its range reaches into the buffer's slack where
    /// [`texel_view_range`] asks for it and the device takes the texels.
    fn texel_view(
        &self,
        buffer: &Buffer,
        format: vk::Format,
        texels: u64,
    ) -> Result<vk::BufferView, GpuError> {
        let texel_bytes = match format {
            vk::Format::R32G32B32A32_UINT => 16,
            vk::Format::R32G32_UINT => 8,
            _ => 4,
        };
        let bytes = texels * texel_bytes;
        let stable = texel_view_range(bytes);
        let range = if stable <= buffer.capacity
            && stable / texel_bytes <= self.info().max_texel_buffer_elements as u64
        {
            stable
        } else {
            bytes
        };
        let info = vk::BufferViewCreateInfo::default()
            .buffer(buffer.raw)
            .format(format)
            .offset(0)
            .range(range);
        // SAFETY: a view of our buffer (created with UNIFORM_TEXEL_BUFFER usage) inside it, in
        // a format the caller checked; the buffer outlives the view (its owner's duty).
        let view = unsafe { self.device.create_buffer_view(&info, None) }
            .map_err(vk_err("vkCreateBufferView"))?;
        self.set_name(view, &format!("{} (view)", buffer.name));
        Ok(view)
    }
}

/// A 2D RGBA8 (unorm) storage image, kept in `GENERAL` layout; bound at set 0, binding 0.
pub struct Image {
    pub(crate) raw: vk::Image,
    pub(crate) view: vk::ImageView,
    allocation: Option<Allocation>,
    width: u32,
    height: u32,
    name: String,
    ctx: Arc<GpuContext>,
}

impl std::fmt::Debug for Image {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Image")
            .field("name", &self.name)
            .field("width", &self.width)
            .field("height", &self.height)
            .finish()
    }
}

impl Image {
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Debug name.
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl Drop for Image {
    fn drop(&mut self) {
        if let Some(a) = self.allocation.take() {
            self.ctx.defer(Garbage::Image(self.raw, self.view, a));
        }
    }
}

impl GpuContext {
    /// Creates a named buffer of `size` bytes with a device address.
    ///
    /// Errors: `size == 0`, or larger than `maxMemoryAllocationSize` ([`GpuError::TooLarge`]:
    /// paging into several allocations is not implemented yet), or out of device memory.
    pub fn create_buffer(
        self: &Arc<Self>,
        name: &str,
        size: u64,
        location: MemLocation,
    ) -> Result<Buffer, GpuError> {
        if size == 0 {
            return Err(GpuError::InvalidArgument(format!(
                "buffer '{name}': size must be non-zero"
            )));
        }
        let max = self.info().max_memory_allocation_size;
        if size > max {
            return Err(GpuError::TooLarge {
                name: name.to_string(),
                size,
                max,
            });
        }
        let class = size_class(size);
        let base = class.unwrap_or(size);
        let capacity = (base + texel_view_slack(base)).min(max);
        let (raw, allocation, address) = match class.and_then(|c| self.reuse_buffer(c, location)) {
            Some(free) => {
                // Renamed only where validation messages quote names: naming costs as much
                // as the reuse saves on small buffers.
                if self.validation_enabled() {
                    self.set_name(free.0, name);
                }
                free
            }
            None => {
                let new = self.raw_buffer(name, capacity, location.to_allocator())?;
                self.set_name(new.0, name);
                new
            }
        };
        Ok(Buffer {
            raw,
            allocation: Some(allocation),
            size,
            capacity,
            address,
            name: name.to_string(),
            location,
            class,
            ctx: Arc::clone(self),
        })
    }

    /// Creates a device-local buffer holding `data` (through a staging buffer).
    pub fn upload<T: bytemuck::Pod>(
        self: &Arc<Self>,
        name: &str,
        data: &[T],
    ) -> Result<Buffer, GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let buffer = self.create_buffer(name, bytes.len() as u64, MemLocation::GpuOnly)?;
        self.write_buffer(&buffer, 0, data)?;
        Ok(buffer)
    }

    /// Writes `data` at byte `offset` of `dst`: memcpy when mapped, else staged in ≤ 64 MiB chunks.
    pub fn write_buffer<T: bytemuck::Pod>(
        self: &Arc<Self>,
        dst: &Buffer,
        offset: u64,
        data: &[T],
    ) -> Result<(), GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        dst.check_range(offset, bytes.len() as u64)?;
        if bytes.is_empty() {
            return Ok(());
        }
        // Small writes go through the upload ring; large ones in chunks of dedicated staging.
        let mut done = 0usize;
        while done < bytes.len() {
            let n = (STAGING_CHUNK as usize).min(bytes.len() - done);
            let mut cmd = self.begin_commands(&format!("upload {}", dst.name))?;
            cmd.upload(dst, offset + done as u64, &bytes[done..done + n])?;
            cmd.submit()?;
            done += n;
        }
        Ok(())
    }

    /// Writes `data` into a host-visible buffer directly through its mapping.
    pub fn write_mapped<T: bytemuck::Pod>(
        &self,
        dst: &mut Buffer,
        offset: u64,
        data: &[T],
    ) -> Result<(), GpuError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        dst.check_range(offset, bytes.len() as u64)?;
        let name = dst.name.clone();
        let mapped = dst.mapped_mut().ok_or_else(|| {
            GpuError::InvalidArgument(format!("buffer '{name}' is not host-visible"))
        })?;
        mapped[offset as usize..offset as usize + bytes.len()].copy_from_slice(bytes);
        Ok(())
    }

    /// Reads the whole buffer back as `T`s (its size must be a multiple of `size_of::<T>()`).
    pub fn download<T: bytemuck::Pod>(self: &Arc<Self>, src: &Buffer) -> Result<Vec<T>, GpuError> {
        let t = std::mem::size_of::<T>() as u64;
        if t == 0 || !src.size.is_multiple_of(t) {
            return Err(GpuError::InvalidArgument(format!(
                "buffer '{}' of {} bytes is not a whole number of {t}-byte elements",
                src.name, src.size
            )));
        }
        self.read_buffer(src, 0, (src.size / t) as usize)
    }

    /// Reads `count` elements of type `T` starting at byte `offset` (staged in ≤ 64 MiB chunks).
    pub fn read_buffer<T: bytemuck::Pod>(
        self: &Arc<Self>,
        src: &Buffer,
        offset: u64,
        count: usize,
    ) -> Result<Vec<T>, GpuError> {
        let len = (count as u64)
            .checked_mul(std::mem::size_of::<T>() as u64)
            .ok_or_else(|| GpuError::InvalidArgument("read size overflows".into()))?;
        src.check_range(offset, len)?;
        let mut out: Vec<T> = vec![T::zeroed(); count];
        if len == 0 {
            return Ok(out);
        }
        let out_bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut out);
        if let Some(m) = src.mapped() {
            out_bytes.copy_from_slice(&m[offset as usize..(offset + len) as usize]);
            return Ok(out);
        }
        // Small reads land in the readback ring; large ones in chunks of dedicated staging.
        let mut done = 0u64;
        while done < len {
            let n = STAGING_CHUNK.min(len - done);
            let mut cmd = self.begin_commands(&format!("readback {}", src.name))?;
            let readback = cmd.readback::<u8>(src, offset + done, n as usize)?;
            cmd.submit_async()?;
            let bytes = readback.read()?;
            out_bytes[done as usize..(done + n) as usize].copy_from_slice(&bytes);
            done += n;
        }
        Ok(out)
    }

    /// Creates a device-local texel buffer holding `texels` (word pairs; at least one, at most
    /// `maxTexelBufferElements`).
    pub fn upload_texels(
        self: &Arc<Self>,
        name: &str,
        texels: &[[u32; 2]],
    ) -> Result<TexelBuffer, GpuError> {
        self.check_texels(&format!("texel buffer '{name}'"), texels.len() as u64)?;
        let buffer = self.upload(name, texels)?;
        Ok(TexelBuffer {
            view: self.texel_view(&buffer, vk::Format::R32G32_UINT, texels.len() as u64)?,
            buffer,
            texels: texels.len() as u64,
        })
    }

    /// Creates a `width` x `height` RGBA8 storage image (transitioned to `GENERAL` layout).
    pub fn create_storage_image(
        self: &Arc<Self>,
        name: &str,
        width: u32,
        height: u32,
    ) -> Result<Image, GpuError> {
        if width == 0 || height == 0 {
            return Err(GpuError::InvalidArgument(format!(
                "image '{name}': size {width}x{height} must be non-zero"
            )));
        }
        let format = vk::Format::R8G8B8A8_UNORM;
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D {
                width,
                height,
                depth: 1,
            })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(
                vk::ImageUsageFlags::STORAGE
                    | vk::ImageUsageFlags::TRANSFER_SRC
                    | vk::ImageUsageFlags::TRANSFER_DST,
            )
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: valid create infos; every error path destroys what was created before it.
        let image = unsafe {
            let raw = self
                .device
                .create_image(&info, None)
                .map_err(vk_err("vkCreateImage"))?;
            let requirements = self.device.get_image_memory_requirements(raw);
            let allocation = match self.allocator().allocate(&AllocationCreateDesc {
                name,
                requirements,
                location: MemoryLocation::GpuOnly,
                linear: false,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            }) {
                Ok(a) => a,
                Err(e) => {
                    self.device.destroy_image(raw, None);
                    return Err(GpuError::from_allocation(name, e));
                }
            };
            if let Err(e) =
                self.device
                    .bind_image_memory(raw, allocation.memory(), allocation.offset())
            {
                self.device.destroy_image(raw, None);
                let _ = self.allocator().free(allocation);
                return Err(vk_err("vkBindImageMemory")(e));
            }
            let view_info = vk::ImageViewCreateInfo::default()
                .image(raw)
                .view_type(vk::ImageViewType::TYPE_2D)
                .format(format)
                .subresource_range(color_range());
            let view = match self.device.create_image_view(&view_info, None) {
                Ok(v) => v,
                Err(e) => {
                    self.device.destroy_image(raw, None);
                    let _ = self.allocator().free(allocation);
                    return Err(vk_err("vkCreateImageView")(e));
                }
            };
            self.set_name(raw, name);
            self.set_name(view, &format!("{name} (view)"));
            Image {
                raw,
                view,
                allocation: Some(allocation),
                width,
                height,
                name: name.to_string(),
                ctx: Arc::clone(self),
            }
        };
        let mut cmd = self.begin_commands(&format!("init {name}"))?;
        cmd.init_image(&image);
        cmd.submit()?;
        Ok(image)
    }

    /// Reads an RGBA8 image back as `width * height * 4` bytes, rows top to bottom.
    pub fn read_image(self: &Arc<Self>, image: &Image) -> Result<Vec<u8>, GpuError> {
        let len = image.width as u64 * image.height as u64 * 4;
        let staging = self.create_buffer(
            &format!("{} (readback staging)", image.name),
            len,
            MemLocation::GpuToCpu,
        )?;
        let mut cmd = self.begin_commands(&format!("readback {}", image.name))?;
        cmd.copy_image_to_buffer(image, &staging);
        cmd.submit()?;
        let m = staging
            .mapped()
            .ok_or_else(|| GpuError::InvalidArgument("staging buffer is not mapped".into()))?;
        Ok(m[..len as usize].to_vec())
    }
}

/// The single colour mip level and layer of our images.
pub(crate) fn color_range() -> vk::ImageSubresourceRange {
    vk::ImageSubresourceRange {
        aspect_mask: vk::ImageAspectFlags::COLOR,
        base_mip_level: 0,
        level_count: 1,
        base_array_layer: 0,
        layer_count: 1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every Vulkan buffer size and every texel view range of it have the same llvmpipe static
    /// state (size not a power of two, range bits 8-15 not all zero), and the view covers the
    /// buffer's bytes without leaving the Vulkan buffer.
    #[test]
    fn texel_views_of_every_size_share_one_static_state() {
        let sizes = (1..=70_000u64)
            .step_by(4)
            .chain((8..32).flat_map(|k| [(1u64 << k) - 4, 1 << k, (1 << k) + 4]));
        for size in sizes {
            let base = size_class(size).unwrap_or(size);
            let capacity = base + texel_view_slack(base);
            assert!(
                !capacity.is_power_of_two(),
                "size {size}: capacity {capacity}"
            );
            let range = texel_view_range(size);
            assert_ne!((range >> 8) & 0xff, 0, "size {size}: range {range}");
            assert!(
                range >= size && range <= capacity,
                "size {size}: {range}, {capacity}"
            );
            assert_eq!(
                range % 8,
                size % 8,
                "size {size}: the texel size still divides it"
            );
        }
    }
}
