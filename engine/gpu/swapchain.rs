//! Presenting to a window: swapchain (recreated on resize and when out of date), frames in flight,
//! the scaled blit of a compute image to the screen, an egui overlay, screenshots and present.
//!
//! Submission is in [`Presenter::end_frame`]: each frame's recording waits on the slot's acquire
//! semaphore, signals the swapchain image's present semaphore (binary: presentation cannot wait
//! on a timeline) and the context's timeline value, and [`Presenter::begin_frame`] waits for that
//! value before the slot is reused (`Submission::wait`).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use gpu_allocator::{AllocationSizes, AllocatorDebugSettings};

use super::memory::color_range;
use super::{
    vk_err, Buffer, Commands, GpuContext, GpuError, Image, MemLocation, PhaseClock, PhaseTime,
    Profiler, Submission, Surface,
};

/// How a [`Presenter`] presents.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PresenterOptions {
    /// FIFO (wait for vertical blank) when true; MAILBOX, else IMMEDIATE, when false.
    pub vsync: bool,
    /// Frames the CPU may record ahead of the GPU (2 or 3; clamped to 1..=4).
    pub frames_in_flight: usize,
}

impl Default for PresenterOptions {
    fn default() -> Self {
        PresenterOptions {
            vsync: true,
            frames_in_flight: 2,
        }
    }
}

/// The frame being recorded, returned by [`Presenter::begin_frame`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameSlot {
    /// Frame-in-flight slot, `0..frames_in_flight`: index the caller's per-slot resources with it
    /// (render targets, parameter buffers, profilers); the slot's previous frame has finished.
    pub index: usize,
    /// Swapchain image size in pixels.
    pub extent: [u32; 2],
}

/// The egui output of one frame, drawn over the blitted image.
pub struct OverlayFrame<'a> {
    /// Tessellated shapes (`egui::Context::tessellate`).
    pub primitives: &'a [egui::ClippedPrimitive],
    /// Texture changes of the frame (always pass them: egui panics if they are not applied).
    pub textures_delta: egui::TexturesDelta,
    /// Physical pixels per egui point.
    pub pixels_per_point: f32,
}

/// Counters of a [`Presenter`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PresenterStats {
    /// Frames submitted.
    pub frames: u64,
    /// Swapchain creations (the first one included).
    pub swapchain_creations: u64,
    /// Time blocked waiting for a frame slot's timeline value, for a swapchain image and in present.
    pub wait: Duration,
    /// Part of `wait`: waiting for frame slots' previous frames (`begin_frame`).
    pub slot_wait: PhaseTime,
    /// Part of `wait`: `vkAcquireNextImageKHR` (and swapchain rebuilds).
    pub acquire: PhaseTime,
    /// Part of `wait`: `vkQueuePresentKHR` (lavapipe copies the image to the X server in it).
    pub present: PhaseTime,
    /// `end_frame`: applying egui texture uploads and frees.
    pub textures: PhaseTime,
    /// `end_frame`: recording the blit, the screenshot copy and the egui overlay.
    pub record: PhaseTime,
    /// `end_frame`: ending the command buffer and `vkQueueSubmit`.
    pub submit: PhaseTime,
    /// Present mode in use, e.g. `FIFO`.
    pub present_mode: String,
    /// Swapchain images.
    pub image_count: u32,
}

/// One frame in flight: its submission (until waited on) and its acquire semaphore.
struct Slot {
    in_flight: Option<Submission>,
    acquired: vk::Semaphore,
}

/// A swapchain and the per-image objects built on it.
struct SwapchainState {
    raw: vk::SwapchainKHR,
    images: Vec<vk::Image>,
    views: Vec<vk::ImageView>,
    framebuffers: Vec<vk::Framebuffer>,
    /// Signalled by the frame that drew image `i`, waited on by its present (one per image, so a
    /// semaphore is never reused while a present may still wait on it).
    rendered: Vec<vk::Semaphore>,
    extent: vk::Extent2D,
}

/// A screenshot copy recorded into a frame: the buffer and the slot whose submission guards it.
struct Screenshot {
    buffer: Buffer,
    slot: usize,
    extent: [u32; 2],
}

/// Presents compute output to a window: swapchain, frames in flight, blit, egui, present.
///
/// Use per frame: [`Presenter::begin_frame`] (waits for the slot, acquires an image; `None` while
/// the window has no area), record passes into a [`Commands`] writing an [`Image`], then
/// [`Presenter::end_frame`] (blit, overlay, submit, present). Call [`Presenter::resize`] on window
/// resizes. The egui renderer uses its own gpu-allocator instance (see `docs/viewer.md`).
pub struct Presenter {
    slots: Vec<Slot>,
    frame: u64,
    current: Option<(usize, u32)>,
    swapchain: Option<SwapchainState>,
    dirty: bool,
    window_extent: [u32; 2],
    format: vk::SurfaceFormatKHR,
    present_mode: vk::PresentModeKHR,
    can_read_back: bool,
    render_pass: vk::RenderPass,
    upload_pool: vk::CommandPool,
    egui: Option<egui_ash_renderer::Renderer<egui_ash_renderer::allocator::GpuAllocator>>,
    egui_allocator: Option<Arc<Mutex<Allocator>>>,
    screenshot: Option<Screenshot>,
    stats: PresenterStats,
    loader: ash::khr::swapchain::Device,
    surface: Surface,
    ctx: Arc<GpuContext>,
}

/// FIFO with `vsync`, else MAILBOX or IMMEDIATE where the surface offers them (FIFO if not).
fn choose_present_mode(
    ctx: &GpuContext,
    surface: &Surface,
    vsync: bool,
) -> Result<vk::PresentModeKHR, GpuError> {
    if vsync {
        return Ok(vk::PresentModeKHR::FIFO);
    }
    // SAFETY: the surface and physical device are live for the call.
    let modes = unsafe {
        surface
            .loader
            .get_physical_device_surface_present_modes(ctx.physical, surface.raw)
    }
    .map_err(vk_err("vkGetPhysicalDeviceSurfacePresentModesKHR"))?;
    Ok([vk::PresentModeKHR::MAILBOX, vk::PresentModeKHR::IMMEDIATE]
        .into_iter()
        .find(|m| modes.contains(m))
        .unwrap_or(vk::PresentModeKHR::FIFO))
}

fn egui_err(e: egui_ash_renderer::RendererError) -> GpuError {
    GpuError::Surface(format!("egui renderer: {e}"))
}

impl Presenter {
    /// Creates the presenter for `surface`, whose window is `window_extent` pixels large.
    pub fn new(
        surface: Surface,
        window_extent: [u32; 2],
        options: PresenterOptions,
    ) -> Result<Presenter, GpuError> {
        let ctx = Arc::clone(&surface.ctx);
        let options = PresenterOptions {
            frames_in_flight: options.frames_in_flight.clamp(1, 4),
            ..options
        };
        // SAFETY: queries and object creation on our device; every object is owned by the
        // presenter and destroyed in its Drop (null handles are ignored there).
        unsafe {
            let formats = surface
                .loader
                .get_physical_device_surface_formats(ctx.physical, surface.raw)
                .map_err(vk_err("vkGetPhysicalDeviceSurfaceFormatsKHR"))?;
            // The renderer writes sRGB-encoded bytes: a UNORM swapchain shows them unchanged.
            let format = [vk::Format::B8G8R8A8_UNORM, vk::Format::R8G8B8A8_UNORM]
                .iter()
                .find_map(|&f| {
                    formats.iter().find(|s| {
                        s.format == f && s.color_space == vk::ColorSpaceKHR::SRGB_NONLINEAR
                    })
                })
                .copied()
                .ok_or_else(|| {
                    GpuError::Surface(format!(
                        "the surface offers no B8G8R8A8/R8G8B8A8 UNORM format: {formats:?}"
                    ))
                })?;
            let present_mode = choose_present_mode(&ctx, &surface, options.vsync)?;
            let loader = ash::khr::swapchain::Device::new(&ctx.instance, &ctx.device);
            let mut presenter = Presenter {
                slots: Vec::new(),
                frame: 0,
                current: None,
                swapchain: None,
                dirty: true,
                window_extent,
                format,
                present_mode,
                can_read_back: false,
                render_pass: vk::RenderPass::null(),
                upload_pool: vk::CommandPool::null(),
                egui: None,
                egui_allocator: None,
                screenshot: None,
                stats: PresenterStats {
                    present_mode: format!("{present_mode:?}"),
                    ..PresenterStats::default()
                },
                loader,
                surface,
                ctx: Arc::clone(&ctx),
            };
            for i in 0..options.frames_in_flight {
                let acquired = ctx
                    .device
                    .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
                    .map_err(vk_err("vkCreateSemaphore"))?;
                ctx.set_name(acquired, &format!("frame {i} acquire"));
                presenter.slots.push(Slot {
                    in_flight: None,
                    acquired,
                });
            }
            presenter.render_pass = create_render_pass(&ctx, format.format)?;
            presenter.upload_pool = ctx
                .device
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(ctx.queue_family)
                        .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                    None,
                )
                .map_err(vk_err("vkCreateCommandPool"))?;
            ctx.set_name(presenter.upload_pool, "egui uploads (pool)");
            // egui's buffers and textures come from an allocator of their own: the context's is
            // not shareable as `Arc<Mutex<_>>` (see docs/viewer.md).
            let allocator = Allocator::new(&AllocatorCreateDesc {
                instance: ctx.instance.clone(),
                device: ctx.device.clone(),
                physical_device: ctx.physical,
                debug_settings: AllocatorDebugSettings::default(),
                buffer_device_address: false,
                allocation_sizes: AllocationSizes::default(),
            })
            .map_err(|e| GpuError::Allocation {
                name: "egui allocator".into(),
                message: e.to_string(),
            })?;
            let allocator = Arc::new(Mutex::new(allocator));
            presenter.egui_allocator = Some(Arc::clone(&allocator));
            presenter.egui = Some(
                egui_ash_renderer::Renderer::with_gpu_allocator(
                    allocator,
                    ctx.device.clone(),
                    egui_ash_renderer::RenderMode::RenderPass(presenter.render_pass),
                    egui_ash_renderer::Options {
                        in_flight_frames: options.frames_in_flight,
                        srgb_framebuffer: false,
                        ..Default::default()
                    },
                )
                .map_err(egui_err)?,
            );
            Ok(presenter)
        }
    }

    /// Records that the window is now `extent` pixels large; the swapchain is rebuilt before the
    /// next frame.
    pub fn resize(&mut self, extent: [u32; 2]) {
        if extent != self.window_extent {
            self.window_extent = extent;
            self.dirty = true;
        }
    }

    /// Switches between FIFO (`vsync`) and MAILBOX / IMMEDIATE (where offered); the swapchain
    /// is rebuilt with the new mode before the next frame.
    pub fn set_vsync(&mut self, vsync: bool) -> Result<(), GpuError> {
        let mode = choose_present_mode(&self.ctx, &self.surface, vsync)?;
        if mode != self.present_mode {
            self.present_mode = mode;
            self.stats.present_mode = format!("{mode:?}");
            self.dirty = true;
        }
        Ok(())
    }

    /// Frames in flight.
    pub fn frames_in_flight(&self) -> usize {
        self.slots.len()
    }

    /// Whether the GPU has finished slot `index`'s last submitted frame (asks the timeline,
    /// never waits; true for a slot with nothing in flight).
    pub fn slot_finished(&self, index: usize) -> Result<bool, GpuError> {
        match self.slots.get(index).and_then(|s| s.in_flight.as_ref()) {
            Some(submission) => submission.is_done(),
            None => Ok(true),
        }
    }

    /// Current swapchain size (`[0, 0]` before the first frame).
    pub fn extent(&self) -> [u32; 2] {
        self.swapchain
            .as_ref()
            .map_or([0, 0], |s| [s.extent.width, s.extent.height])
    }

    /// Counters so far.
    pub fn stats(&self) -> &PresenterStats {
        &self.stats
    }

    /// Waits until the next slot's previous frame has finished and acquires a swapchain image,
    /// rebuilding the swapchain first when resized or out of date. `None`: the window has no area
    /// (minimised); try again later. A returned frame must be ended with [`Presenter::end_frame`].
    pub fn begin_frame(&mut self) -> Result<Option<FrameSlot>, GpuError> {
        if self.current.is_some() {
            return Err(GpuError::InvalidArgument(
                "Presenter::begin_frame called twice without end_frame".into(),
            ));
        }
        let mut clock = PhaseClock::start();
        let start = clock.instant();
        let index = (self.frame % self.slots.len() as u64) as usize;
        if let Some(done) = self.slots[index].in_flight.take() {
            done.wait()?;
        }
        self.stats.slot_wait += clock.lap();
        let result = self.acquire(index);
        self.stats.acquire += clock.lap();
        self.stats.wait += clock.instant() - start;
        let Some(image) = result? else {
            return Ok(None);
        };
        self.current = Some((index, image));
        Ok(Some(FrameSlot {
            index,
            extent: self.extent(),
        }))
    }

    /// Acquires an image for slot `index`, rebuilding the swapchain when needed (at most twice).
    fn acquire(&mut self, index: usize) -> Result<Option<u32>, GpuError> {
        for _ in 0..3 {
            if (self.dirty || self.swapchain.is_none()) && !self.recreate()? {
                return Ok(None);
            }
            let sc = self.swapchain.as_ref().expect("created above");
            // SAFETY: the slot's semaphore is unsignalled: its last use was waited on by the
            // slot's previous submission, which has finished.
            let acquired = unsafe {
                self.loader.acquire_next_image(
                    sc.raw,
                    u64::MAX,
                    self.slots[index].acquired,
                    vk::Fence::null(),
                )
            };
            match acquired {
                Ok((image, suboptimal)) => {
                    // Use the image; rebuild before the next frame.
                    self.dirty |= suboptimal;
                    return Ok(Some(image));
                }
                Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => self.dirty = true,
                Err(e) => return Err(vk_err("vkAcquireNextImageKHR")(e)),
            }
        }
        Err(GpuError::Surface(
            "the swapchain stays out of date after being rebuilt".into(),
        ))
    }

    /// Rebuilds the swapchain at the surface's current size; false when the window has no area.
    fn recreate(&mut self) -> Result<bool, GpuError> {
        self.ctx.wait_idle()?;
        for slot in &mut self.slots {
            if let Some(done) = slot.in_flight.take() {
                done.wait()?;
            }
        }
        // SAFETY: the device is idle, so no old swapchain object is in use; new objects are
        // owned by `self.swapchain` and destroyed with it.
        unsafe {
            let caps = self
                .surface
                .loader
                .get_physical_device_surface_capabilities(self.ctx.physical, self.surface.raw)
                .map_err(vk_err("vkGetPhysicalDeviceSurfaceCapabilitiesKHR"))?;
            let extent = if caps.current_extent.width != u32::MAX {
                caps.current_extent
            } else {
                vk::Extent2D {
                    width: self.window_extent[0]
                        .clamp(caps.min_image_extent.width, caps.max_image_extent.width),
                    height: self.window_extent[1]
                        .clamp(caps.min_image_extent.height, caps.max_image_extent.height),
                }
            };
            if extent.width == 0 || extent.height == 0 {
                return Ok(false);
            }
            let mut count = (caps.min_image_count + 1).max(self.slots.len() as u32);
            if caps.max_image_count > 0 {
                count = count.min(caps.max_image_count);
            }
            self.can_read_back = caps
                .supported_usage_flags
                .contains(vk::ImageUsageFlags::TRANSFER_SRC);
            let mut usage =
                vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_DST;
            if self.can_read_back {
                usage |= vk::ImageUsageFlags::TRANSFER_SRC;
            }
            let old = self.swapchain.take();
            let info = vk::SwapchainCreateInfoKHR::default()
                .surface(self.surface.raw)
                .min_image_count(count)
                .image_format(self.format.format)
                .image_color_space(self.format.color_space)
                .image_extent(extent)
                .image_array_layers(1)
                .image_usage(usage)
                .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
                .pre_transform(caps.current_transform)
                .composite_alpha(vk::CompositeAlphaFlagsKHR::OPAQUE)
                .present_mode(self.present_mode)
                .clipped(true)
                .old_swapchain(old.as_ref().map_or(vk::SwapchainKHR::null(), |o| o.raw));
            let created = self.loader.create_swapchain(&info, None);
            if let Some(old) = old {
                self.destroy_swapchain(old);
            }
            let raw = created.map_err(vk_err("vkCreateSwapchainKHR"))?;
            self.ctx.set_name(raw, "swapchain");
            let mut state = SwapchainState {
                raw,
                images: Vec::new(),
                views: Vec::new(),
                framebuffers: Vec::new(),
                rendered: Vec::new(),
                extent,
            };
            let built = self.build_image_objects(&mut state);
            let image_count = state.images.len() as u32;
            self.swapchain = Some(state);
            built?;
            self.dirty = false;
            self.stats.swapchain_creations += 1;
            self.stats.image_count = image_count;
            log::info!(
                "swapchain {}x{}, {} images, {:?}, {:?}",
                extent.width,
                extent.height,
                image_count,
                self.format.format,
                self.present_mode
            );
            Ok(true)
        }
    }

    /// Views, framebuffers and present semaphores of the swapchain's images.
    unsafe fn build_image_objects(&self, state: &mut SwapchainState) -> Result<(), GpuError> {
        let device = &self.ctx.device;
        state.images = self
            .loader
            .get_swapchain_images(state.raw)
            .map_err(vk_err("vkGetSwapchainImagesKHR"))?;
        for (i, &image) in state.images.iter().enumerate() {
            let view = device
                .create_image_view(
                    &vk::ImageViewCreateInfo::default()
                        .image(image)
                        .view_type(vk::ImageViewType::TYPE_2D)
                        .format(self.format.format)
                        .subresource_range(color_range()),
                    None,
                )
                .map_err(vk_err("vkCreateImageView"))?;
            state.views.push(view);
            let attachments = [view];
            let framebuffer = device
                .create_framebuffer(
                    &vk::FramebufferCreateInfo::default()
                        .render_pass(self.render_pass)
                        .attachments(&attachments)
                        .width(state.extent.width)
                        .height(state.extent.height)
                        .layers(1),
                    None,
                )
                .map_err(vk_err("vkCreateFramebuffer"))?;
            state.framebuffers.push(framebuffer);
            let rendered = device
                .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
                .map_err(vk_err("vkCreateSemaphore"))?;
            self.ctx
                .set_name(rendered, &format!("swapchain image {i} rendered"));
            state.rendered.push(rendered);
        }
        Ok(())
    }

    /// Destroys a swapchain and its per-image objects (the device must be idle).
    unsafe fn destroy_swapchain(&self, state: SwapchainState) {
        let device = &self.ctx.device;
        for f in state.framebuffers {
            device.destroy_framebuffer(f, None);
        }
        for v in state.views {
            device.destroy_image_view(v, None);
        }
        for s in state.rendered {
            device.destroy_semaphore(s, None);
        }
        self.loader.destroy_swapchain(state.raw, None);
    }

    /// Ends the frame begun by [`Presenter::begin_frame`]: blits the top-left `source_extent`
    /// pixels of `source` (written by compute passes in `cmd`, in `GENERAL` layout) scaled to the
    /// whole swapchain image (nearest when the sizes match, so the bytes are copied unchanged,
    /// else linear), draws `overlay` over it, submits `cmd` and presents. With `screenshot`, the
    /// swapchain image is also copied to the host after the blit and before the overlay; read it
    /// with [`Presenter::take_screenshot`]. `profiler` times the blit and overlay as the pass
    /// "present" (resolve it once the slot comes round again).
    pub fn end_frame(
        &mut self,
        mut cmd: Commands<'_>,
        source: &Image,
        source_extent: [u32; 2],
        overlay: Option<OverlayFrame<'_>>,
        screenshot: bool,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        let (slot, image_index) = self.current.take().ok_or_else(|| {
            GpuError::InvalidArgument("Presenter::end_frame without begin_frame".into())
        })?;
        if source_extent[0] == 0
            || source_extent[1] == 0
            || source_extent[0] > source.width()
            || source_extent[1] > source.height()
        {
            return Err(GpuError::InvalidArgument(format!(
                "blit source {source_extent:?} outside image '{}' ({}x{})",
                source.name(),
                source.width(),
                source.height()
            )));
        }
        if screenshot && !self.can_read_back {
            return Err(GpuError::Surface(
                "this surface's swapchain images cannot be copied (no TRANSFER_SRC usage)".into(),
            ));
        }
        let (extent, image, framebuffer, rendered) = {
            let sc = self.swapchain.as_ref().expect("acquired in begin_frame");
            let i = image_index as usize;
            (sc.extent, sc.images[i], sc.framebuffers[i], sc.rendered[i])
        };
        if screenshot {
            let size = [extent.width, extent.height];
            let reuse = self.screenshot.as_ref().is_some_and(|s| s.extent == size);
            if !reuse {
                // Any previous screenshot buffer belongs to a finished frame (same slot, or the
                // device was idled by a swapchain rebuild) or to a different size: replace it.
                self.ctx.wait_idle()?;
                self.screenshot = Some(Screenshot {
                    buffer: self.ctx.create_buffer(
                        "screenshot readback",
                        extent.width as u64 * extent.height as u64 * 4,
                        MemLocation::GpuToCpu,
                    )?,
                    slot,
                    extent: size,
                });
            }
            if let Some(s) = &mut self.screenshot {
                s.slot = slot;
            }
        }
        let mut clock = PhaseClock::start();
        let overlay = match overlay {
            Some(o) => Some(self.apply_textures(o)?),
            None => None,
        };
        self.stats.textures += clock.lap();
        if let Some(p) = profiler.as_deref_mut() {
            p.begin_pass(&mut cmd, "present");
        }
        let device = &self.ctx.device;
        let raw = cmd.raw;
        cmd.before_command();
        // SAFETY: recording into the frame's command buffer; the swapchain image was acquired
        // for it, and its layout is set explicitly (UNDEFINED: its old contents are discarded).
        unsafe {
            // Storage images live in GENERAL; the blit reads from TRANSFER_SRC_OPTIMAL.
            let source_ready = layout_barrier(
                source.raw,
                (
                    vk::ImageLayout::GENERAL,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                ),
                (
                    vk::AccessFlags::SHADER_WRITE,
                    vk::AccessFlags::TRANSFER_READ,
                ),
            );
            let target_ready = layout_barrier(
                image,
                (
                    vk::ImageLayout::UNDEFINED,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                ),
                (vk::AccessFlags::empty(), vk::AccessFlags::TRANSFER_WRITE),
            );
            device.cmd_pipeline_barrier(
                raw,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[source_ready, target_ready],
            );
            let corner = |w: u32, h: u32| {
                [
                    vk::Offset3D::default(),
                    vk::Offset3D {
                        x: w as i32,
                        y: h as i32,
                        z: 1,
                    },
                ]
            };
            let layers = vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: 1,
            };
            let blit = vk::ImageBlit {
                src_subresource: layers,
                src_offsets: corner(source_extent[0], source_extent[1]),
                dst_subresource: layers,
                dst_offsets: corner(extent.width, extent.height),
            };
            let same_size = source_extent == [extent.width, extent.height];
            device.cmd_blit_image(
                raw,
                source.raw,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[blit],
                if same_size {
                    vk::Filter::NEAREST
                } else {
                    vk::Filter::LINEAR
                },
            );
            device.cmd_pipeline_barrier(
                raw,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[layout_barrier(
                    source.raw,
                    (
                        vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                        vk::ImageLayout::GENERAL,
                    ),
                    (
                        vk::AccessFlags::TRANSFER_READ,
                        vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE,
                    ),
                )],
            );
            let mut layout = vk::ImageLayout::TRANSFER_DST_OPTIMAL;
            let mut access = vk::AccessFlags::TRANSFER_WRITE;
            if screenshot {
                let s = self.screenshot.as_ref().expect("created above");
                device.cmd_pipeline_barrier(
                    raw,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[layout_barrier(
                        image,
                        (layout, vk::ImageLayout::TRANSFER_SRC_OPTIMAL),
                        (access, vk::AccessFlags::TRANSFER_READ),
                    )],
                );
                let region = vk::BufferImageCopy {
                    buffer_offset: 0,
                    buffer_row_length: 0,
                    buffer_image_height: 0,
                    image_subresource: layers,
                    image_offset: vk::Offset3D::default(),
                    image_extent: vk::Extent3D {
                        width: extent.width,
                        height: extent.height,
                        depth: 1,
                    },
                };
                device.cmd_copy_image_to_buffer(
                    raw,
                    image,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    s.buffer.raw,
                    &[region],
                );
                let to_host = vk::BufferMemoryBarrier::default()
                    .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
                    .dst_access_mask(vk::AccessFlags::HOST_READ)
                    .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                    .buffer(s.buffer.raw)
                    .offset(0)
                    .size(vk::WHOLE_SIZE);
                device.cmd_pipeline_barrier(
                    raw,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::HOST,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[to_host],
                    &[],
                );
                layout = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
                access = vk::AccessFlags::TRANSFER_READ;
            }
            device.cmd_pipeline_barrier(
                raw,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[layout_barrier(
                    image,
                    (layout, vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL),
                    (
                        access,
                        vk::AccessFlags::COLOR_ATTACHMENT_READ
                            | vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                    ),
                )],
            );
            let area = vk::Rect2D {
                offset: vk::Offset2D::default(),
                extent,
            };
            device.cmd_begin_render_pass(
                raw,
                &vk::RenderPassBeginInfo::default()
                    .render_pass(self.render_pass)
                    .framebuffer(framebuffer)
                    .render_area(area),
                vk::SubpassContents::INLINE,
            );
            if let (Some((primitives, ppp)), Some(egui)) = (overlay, self.egui.as_mut()) {
                egui.cmd_draw(raw, extent, ppp, primitives)
                    .map_err(egui_err)?;
            }
            device.cmd_end_render_pass(raw);
        }
        if let Some(p) = profiler {
            p.end_pass(&mut cmd);
        }
        self.stats.record += clock.lap();
        // Waits for the slot's acquired image at the blit, signals the image's present semaphore
        // (binary: presentation cannot wait on a timeline) and the context's timeline value.
        let submission = cmd.submit_async_with(
            &[(self.slots[slot].acquired, vk::PipelineStageFlags::TRANSFER)],
            &[rendered],
        )?;
        self.stats.submit += clock.lap();
        self.slots[slot].in_flight = Some(submission);
        self.frame += 1;
        self.stats.frames += 1;
        self.present(image_index, rendered)
    }

    /// Applies the frame's egui texture uploads (frees wait for the device: they are rare) and
    /// returns what to draw.
    fn apply_textures<'o>(
        &mut self,
        overlay: OverlayFrame<'o>,
    ) -> Result<(&'o [egui::ClippedPrimitive], f32), GpuError> {
        let OverlayFrame {
            primitives,
            mut textures_delta,
            pixels_per_point,
        } = overlay;
        let egui = self.egui.as_mut().expect("created in new");
        if !textures_delta.set.is_empty() {
            // egui-ash-renderer submits the upload on the queue and waits for it.
            let queue = self.ctx.queue();
            for (id, deltas) in textures_delta.set.drain() {
                for delta in deltas {
                    egui.set_texture(*queue, self.upload_pool, id, &delta)
                        .map_err(egui_err)?;
                }
            }
        }
        if !textures_delta.free.is_empty() {
            self.ctx.wait_idle()?;
            for id in textures_delta.free.drain() {
                egui.free_texture(id).map_err(egui_err)?;
            }
        }
        Ok((primitives, pixels_per_point))
    }

    /// Presents image `index` once `rendered` is signalled; out of date or suboptimal marks the
    /// swapchain for a rebuild before the next frame.
    fn present(&mut self, index: u32, rendered: vk::Semaphore) -> Result<(), GpuError> {
        let mut clock = PhaseClock::start();
        let sc = self.swapchain.as_ref().expect("acquired in begin_frame");
        let waits = [rendered];
        let swapchains = [sc.raw];
        let indices = [index];
        let info = vk::PresentInfoKHR::default()
            .wait_semaphores(&waits)
            .swapchains(&swapchains)
            .image_indices(&indices);
        let result = {
            let queue = self.ctx.queue();
            // SAFETY: the image was acquired and its frame submitted to signal `rendered`.
            unsafe { self.loader.queue_present(*queue, &info) }
        };
        let elapsed = clock.lap();
        self.stats.present += elapsed;
        self.stats.wait += elapsed.wall;
        match result {
            Ok(false) => Ok(()),
            Ok(true) | Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => {
                self.dirty = true;
                Ok(())
            }
            Err(e) => Err(vk_err("vkQueuePresentKHR")(e)),
        }
    }

    /// The swapchain image copied by the last `end_frame(.., screenshot = true)` as RGBA8 rows
    /// top to bottom (waits for that frame), or `None` when no screenshot was recorded.
    pub fn take_screenshot(&mut self) -> Result<Option<(u32, u32, Vec<u8>)>, GpuError> {
        let Some(shot) = self.screenshot.take() else {
            return Ok(None);
        };
        if let Some(done) = self.slots[shot.slot].in_flight.take() {
            done.wait()?;
        }
        let mut pixels: Vec<u8> = self.ctx.download(&shot.buffer)?;
        if self.format.format == vk::Format::B8G8R8A8_UNORM {
            for p in pixels.chunks_exact_mut(4) {
                p.swap(0, 2);
            }
        }
        Ok(Some((shot.extent[0], shot.extent[1], pixels)))
    }
}

/// A whole-image layout transition: (old, new) layouts and (src, dst) accesses.
fn layout_barrier(
    image: vk::Image,
    layouts: (vk::ImageLayout, vk::ImageLayout),
    access: (vk::AccessFlags, vk::AccessFlags),
) -> vk::ImageMemoryBarrier<'static> {
    vk::ImageMemoryBarrier::default()
        .src_access_mask(access.0)
        .dst_access_mask(access.1)
        .old_layout(layouts.0)
        .new_layout(layouts.1)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .image(image)
        .subresource_range(color_range())
}

/// The overlay's render pass: loads the blitted image, draws egui, leaves it ready to present.
fn create_render_pass(ctx: &GpuContext, format: vk::Format) -> Result<vk::RenderPass, GpuError> {
    let attachments = [vk::AttachmentDescription::default()
        .format(format)
        .samples(vk::SampleCountFlags::TYPE_1)
        .load_op(vk::AttachmentLoadOp::LOAD)
        .store_op(vk::AttachmentStoreOp::STORE)
        .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
        .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
        .initial_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
        .final_layout(vk::ImageLayout::PRESENT_SRC_KHR)];
    let color = [vk::AttachmentReference {
        attachment: 0,
        layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL,
    }];
    let subpasses = [vk::SubpassDescription::default()
        .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
        .color_attachments(&color)];
    let dependencies = [vk::SubpassDependency {
        src_subpass: vk::SUBPASS_EXTERNAL,
        dst_subpass: 0,
        src_stage_mask: vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
        dst_stage_mask: vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
        src_access_mask: vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
        dst_access_mask: vk::AccessFlags::COLOR_ATTACHMENT_READ
            | vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
        dependency_flags: vk::DependencyFlags::empty(),
    }];
    // SAFETY: valid create info; destroyed in the presenter's Drop.
    let pass = unsafe {
        ctx.device.create_render_pass(
            &vk::RenderPassCreateInfo::default()
                .attachments(&attachments)
                .subpasses(&subpasses)
                .dependencies(&dependencies),
            None,
        )
    }
    .map_err(vk_err("vkCreateRenderPass"))?;
    ctx.set_name(pass, "overlay render pass");
    Ok(pass)
}

impl Drop for Presenter {
    fn drop(&mut self) {
        let _ = self.ctx.wait_idle();
        for slot in &mut self.slots {
            if let Some(done) = slot.in_flight.take() {
                let _ = done.wait();
            }
        }
        self.screenshot = None;
        // egui's objects go before its allocator, the allocator before the device.
        self.egui = None;
        if let Some(allocator) = self.egui_allocator.take() {
            if let Ok(a) = allocator.lock() {
                if !a.generate_report().allocations.is_empty() {
                    a.report_memory_leaks(log::Level::Error);
                }
            }
        }
        // SAFETY: the device is idle; every handle below is owned by the presenter and
        // destroyed once (null handles are ignored).
        unsafe {
            if let Some(sc) = self.swapchain.take() {
                self.destroy_swapchain(sc);
            }
            let device = &self.ctx.device;
            for slot in &self.slots {
                device.destroy_semaphore(slot.acquired, None);
            }
            device.destroy_render_pass(self.render_pass, None);
            device.destroy_command_pool(self.upload_pool, None);
        }
        // `surface` is dropped after this, with the swapchain already gone.
    }
}
