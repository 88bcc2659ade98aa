//! A window's Vulkan surface (`VK_KHR_surface` + the platform's surface extension, via ash-window).

use std::sync::Arc;

use ash::vk;
use raw_window_handle::{RawDisplayHandle, RawWindowHandle};

use super::{vk_err, GpuContext, GpuError};

/// A `VkSurfaceKHR` for one window; destroyed on drop (after the swapchain built on it).
///
/// The window must outlive the surface: the caller keeps it alive (e.g. in an `Arc`) and drops the
/// [`super::Presenter`] that owns the surface first.
pub struct Surface {
    pub(crate) raw: vk::SurfaceKHR,
    pub(crate) loader: ash::khr::surface::Instance,
    pub(crate) ctx: Arc<GpuContext>,
}

impl Surface {
    /// Creates the surface of a window. The context must have been created with
    /// [`super::GpuOptions::display`] set to the window's display, and its queue must be able to
    /// present to the surface.
    ///
    /// # Safety
    /// `display` and `window` must be valid handles of a live window that outlives the surface.
    pub unsafe fn new(
        ctx: &Arc<GpuContext>,
        display: RawDisplayHandle,
        window: RawWindowHandle,
    ) -> Result<Surface, GpuError> {
        if !ctx.presentation {
            return Err(GpuError::Surface(
                "the GPU context was created without a display (GpuOptions::display)".into(),
            ));
        }
        let raw = ash_window::create_surface(&ctx.entry, &ctx.instance, display, window, None)
            .map_err(vk_err("vkCreate*SurfaceKHR"))?;
        let loader = ash::khr::surface::Instance::new(&ctx.entry, &ctx.instance);
        let surface = Surface {
            raw,
            loader,
            ctx: Arc::clone(ctx),
        };
        let supported = surface
            .loader
            .get_physical_device_surface_support(ctx.physical, ctx.queue_family, raw)
            .map_err(vk_err("vkGetPhysicalDeviceSurfaceSupportKHR"))?;
        if !supported {
            return Err(GpuError::Surface(format!(
                "queue family {} of {} cannot present to this window",
                ctx.queue_family,
                ctx.info().name
            )));
        }
        Ok(surface)
    }
}

impl Drop for Surface {
    fn drop(&mut self) {
        // SAFETY: created by this instance; the swapchain that used it is gone (it lives in the
        // presenter, which drops its swapchain before its surface).
        unsafe { self.loader.destroy_surface(self.raw, None) };
    }
}
