//! Instance, device selection, logical device, allocator and validation messenger.

use std::ffi::{c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use gpu_allocator::{AllocationSizes, AllocatorDebugSettings};

use super::{vk_err, GpuError};

/// Options for [`GpuContext::new`].
#[derive(Clone, Debug)]
pub struct GpuOptions {
    /// Enable `VK_LAYER_KHRONOS_validation` when installed (default: env `VOXDAG_VALIDATION`,
    /// else on in debug builds and off in release builds).
    pub validation: bool,
    /// Pick the first device whose name contains this (case-insensitive) substring
    /// (default: env `VOXDAG_DEVICE`).
    pub device: Option<String>,
    /// Present to windows of this display (`voxdag view`): enables the surface instance extensions
    /// it needs and `VK_KHR_swapchain`. `None` (the default) keeps the context headless.
    pub display: Option<raw_window_handle::RawDisplayHandle>,
}

impl Default for GpuOptions {
    fn default() -> Self {
        let validation = match std::env::var("VOXDAG_VALIDATION").ok().as_deref() {
            Some("0") | Some("false") | Some("off") => false,
            Some("1") | Some("true") | Some("on") => true,
            _ => cfg!(debug_assertions),
        };
        let device = std::env::var("VOXDAG_DEVICE")
            .ok()
            .filter(|s| !s.trim().is_empty());
        GpuOptions {
            validation,
            device,
            display: None,
        }
    }
}

/// What the chosen device is and the limits that matter to voxdag.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// Device name, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`.
    pub name: String,
    /// Device type: `discrete`, `integrated`, `virtual`, `cpu` or `other`.
    pub device_type: String,
    /// Driver name, e.g. `llvmpipe`.
    pub driver_name: String,
    /// Driver info string, e.g. `Mesa 22.3.6 (LLVM 15.0.6)`.
    pub driver_info: String,
    /// Supported Vulkan API version (major, minor, patch).
    pub api_version: (u32, u32, u32),
    /// Default subgroup size (8 on lavapipe, 32 on NVIDIA, 32 or 64 on AMD).
    pub subgroup_size: u32,
    /// `maxStorageBufferRange`: largest range bindable as a storage buffer descriptor.
    pub max_storage_buffer_range: u32,
    /// `maxMemoryAllocationSize`: largest single allocation (and so largest buffer).
    pub max_memory_allocation_size: u64,
    /// Nanoseconds per timestamp tick.
    pub timestamp_period: f32,
    /// Valid bits of timestamps on the chosen queue; 0 = no GPU profiling.
    pub timestamp_valid_bits: u32,
    /// `maxComputeWorkGroupSize`.
    pub max_compute_workgroup_size: [u32; 3],
    /// `maxComputeWorkGroupInvocations`.
    pub max_compute_workgroup_invocations: u32,
    /// `maxComputeWorkGroupCount`.
    pub max_compute_workgroup_count: [u32; 3],
    /// `maxPushConstantsSize` in bytes.
    pub max_push_constants_size: u32,
    /// Whether `storageBuffer8BitAccess` was enabled.
    pub storage_buffer_8bit: bool,
    /// Whether `scalarBlockLayout` was enabled.
    pub scalar_block_layout: bool,
    /// Whether timeline semaphores were enabled.
    pub timeline_semaphores: bool,
}

/// Counts validation warnings and errors reported through `VK_EXT_debug_utils`.
#[derive(Default)]
struct MessengerState {
    problems: AtomicUsize,
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    let message = if data.is_null() || (*data).p_message.is_null() {
        String::from("(no message)")
    } else {
        CStr::from_ptr((*data).p_message)
            .to_string_lossy()
            .into_owned()
    };
    let problem = severity.intersects(
        vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
            | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
    );
    if problem {
        if !user.is_null() {
            (*(user as *const MessengerState))
                .problems
                .fetch_add(1, Ordering::SeqCst);
        }
        if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
            log::error!("vulkan {types:?}: {message}");
        } else {
            log::warn!("vulkan {types:?}: {message}");
        }
    } else {
        log::debug!("vulkan {types:?}: {message}");
    }
    vk::FALSE
}

/// The Vulkan device and everything shared by all GPU objects; create once, share as `Arc`.
///
/// Every resource ([`super::Buffer`], [`super::Image`], [`super::ComputePipeline`], ...) holds an
/// `Arc<GpuContext>` and destroys its own Vulkan objects on drop, so the context outlives them and
/// its `Drop` (which waits for the device to be idle) runs last.
pub struct GpuContext {
    pub(crate) entry: ash::Entry,
    pub(crate) instance: ash::Instance,
    debug_instance: Option<ash::ext::debug_utils::Instance>,
    messenger: vk::DebugUtilsMessengerEXT,
    messenger_state: Box<MessengerState>,
    pub(crate) device: ash::Device,
    pub(crate) debug_device: Option<ash::ext::debug_utils::Device>,
    queue: Mutex<vk::Queue>,
    /// Family of `queue`; every [`super::Commands`] creates its own command pool for it.
    pub(crate) queue_family: u32,
    allocator: ManuallyDrop<Mutex<Allocator>>,
    info: DeviceInfo,
    validation: bool,
    /// Whether the surface and swapchain extensions are enabled ([`GpuOptions::display`]).
    pub(crate) presentation: bool,
    /// The chosen physical device (surface queries).
    pub(crate) physical: vk::PhysicalDevice,
}

/// A physical device candidate during selection.
struct Candidate {
    physical: vk::PhysicalDevice,
    name: String,
    rank: u32,
    type_name: &'static str,
    api: u32,
}

fn type_rank(t: vk::PhysicalDeviceType) -> (u32, &'static str) {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => (0, "discrete"),
        vk::PhysicalDeviceType::INTEGRATED_GPU => (1, "integrated"),
        vk::PhysicalDeviceType::VIRTUAL_GPU => (2, "virtual"),
        vk::PhysicalDeviceType::CPU => (4, "cpu"),
        _ => (3, "other"),
    }
}

fn cstr_field(r: Result<&CStr, std::ffi::FromBytesUntilNulError>) -> String {
    r.map(|c| c.to_string_lossy().into_owned())
        .unwrap_or_default()
}

impl GpuContext {
    /// Creates the instance and device, choosing discrete > integrated > virtual > other > CPU
    /// (lavapipe) unless `options.device` names one.
    pub fn new(options: &GpuOptions) -> Result<Arc<GpuContext>, GpuError> {
        // SAFETY: loading the system Vulkan loader; all later calls follow the Vulkan spec's
        // valid-usage rules (handles created here, destroyed once in Drop).
        unsafe { Self::create(options) }
    }

    unsafe fn create(options: &GpuOptions) -> Result<Arc<GpuContext>, GpuError> {
        let entry = ash::Entry::load().map_err(|e| {
            GpuError::NoVulkan(format!(
                "cannot load the Vulkan loader ({e}); install libvulkan1 and a driver \
                 (e.g. mesa-vulkan-drivers for lavapipe)"
            ))
        })?;
        let instance_version = entry
            .try_enumerate_instance_version()
            .map_err(vk_err("vkEnumerateInstanceVersion"))?
            .unwrap_or(vk::API_VERSION_1_0);
        if instance_version < vk::API_VERSION_1_2 {
            return Err(GpuError::NoVulkan(format!(
                "the Vulkan loader supports only {}.{}; voxdag needs 1.2",
                vk::api_version_major(instance_version),
                vk::api_version_minor(instance_version)
            )));
        }

        let layers = entry
            .enumerate_instance_layer_properties()
            .map_err(vk_err("vkEnumerateInstanceLayerProperties"))?;
        let validation_name = c"VK_LAYER_KHRONOS_validation";
        let has_validation = layers
            .iter()
            .any(|l| l.layer_name_as_c_str().ok() == Some(validation_name));
        let validation = options.validation && has_validation;
        if options.validation && !has_validation {
            log::warn!(
                "validation requested but VK_LAYER_KHRONOS_validation is not installed \
                 (apt-get install vulkan-validationlayers)"
            );
        }
        let extensions = entry
            .enumerate_instance_extension_properties(None)
            .map_err(vk_err("vkEnumerateInstanceExtensionProperties"))?;
        let has_debug_utils = extensions
            .iter()
            .any(|e| e.extension_name_as_c_str().ok() == Some(ash::ext::debug_utils::NAME));

        let app_name = c"voxdag";
        let app_info = vk::ApplicationInfo::default()
            .application_name(app_name)
            .application_version(0)
            .engine_name(app_name)
            .engine_version(0)
            .api_version(vk::API_VERSION_1_2);
        let layer_ptrs: Vec<*const std::ffi::c_char> = if validation {
            vec![validation_name.as_ptr()]
        } else {
            Vec::new()
        };
        let mut ext_ptrs: Vec<*const std::ffi::c_char> = if has_debug_utils {
            vec![ash::ext::debug_utils::NAME.as_ptr()]
        } else {
            Vec::new()
        };
        if let Some(display) = options.display {
            let surface_exts = ash_window::enumerate_required_extensions(display).map_err(|e| {
                GpuError::Surface(format!("no Vulkan surface support for this display: {e:?}"))
            })?;
            ext_ptrs.extend_from_slice(surface_exts);
        }
        let messenger_state = Box::<MessengerState>::default();
        let user_ptr = &*messenger_state as *const MessengerState as *mut c_void;
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::ERROR
                    | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                    | vk::DebugUtilsMessageSeverityFlagsEXT::INFO,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(debug_callback))
            .user_data(user_ptr);
        let mut instance_info = vk::InstanceCreateInfo::default()
            .application_info(&app_info)
            .enabled_layer_names(&layer_ptrs)
            .enabled_extension_names(&ext_ptrs);
        if has_debug_utils {
            // Also catches messages from vkCreateInstance / vkDestroyInstance.
            instance_info = instance_info.push_next(&mut messenger_info);
        }
        let instance = entry
            .create_instance(&instance_info, None)
            .map_err(vk_err("vkCreateInstance"))?;

        // From here on, clean up the instance on every error path.
        let mut guard = InstanceGuard {
            instance: Some(instance.clone()),
            debug: None,
            messenger: vk::DebugUtilsMessengerEXT::null(),
        };
        let (debug_instance, messenger) = if has_debug_utils {
            let di = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let m = di
                .create_debug_utils_messenger(&messenger_info, None)
                .map_err(vk_err("vkCreateDebugUtilsMessengerEXT"))?;
            guard.debug = Some(di.clone());
            guard.messenger = m;
            (Some(di), m)
        } else {
            (None, vk::DebugUtilsMessengerEXT::null())
        };

        let physical_devices = instance
            .enumerate_physical_devices()
            .map_err(vk_err("vkEnumeratePhysicalDevices"))?;
        let mut candidates = Vec::new();
        for &pd in &physical_devices {
            let props = instance.get_physical_device_properties(pd);
            let (rank, type_name) = type_rank(props.device_type);
            candidates.push(Candidate {
                physical: pd,
                name: cstr_field(props.device_name_as_c_str()),
                rank,
                type_name,
                api: props.api_version,
            });
        }
        let listing = candidates
            .iter()
            .map(|c| format!("\"{}\" ({})", c.name, c.type_name))
            .collect::<Vec<_>>()
            .join(", ");
        // Keep only devices that can run voxdag.
        let mut usable: Vec<&Candidate> = candidates
            .iter()
            .filter(|c| {
                c.api >= vk::API_VERSION_1_2 && Self::supports_required(&instance, c.physical)
            })
            .collect();
        usable.sort_by_key(|c| c.rank);
        let chosen = match &options.device {
            Some(wanted) => {
                let w = wanted.to_lowercase();
                *usable
                    .iter()
                    .find(|c| c.name.to_lowercase().contains(&w))
                    .ok_or_else(|| GpuError::DeviceNotFound {
                        wanted: wanted.clone(),
                        available: if listing.is_empty() {
                            "none".into()
                        } else {
                            listing.clone()
                        },
                    })?
            }
            None => *usable.first().ok_or_else(|| {
                GpuError::NoDevice(if listing.is_empty() {
                    "no Vulkan devices found".into()
                } else {
                    format!(
                        "none of {listing} supports Vulkan 1.2 with bufferDeviceAddress, \
                         shaderInt64 and a compute queue"
                    )
                })
            })?,
        };
        let physical = chosen.physical;

        // Queue: prefer a universal (graphics + compute) family, else any compute family.
        let families = instance.get_physical_device_queue_family_properties(physical);
        let queue_family = families
            .iter()
            .position(|f| {
                f.queue_flags
                    .contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE)
            })
            .or_else(|| {
                families
                    .iter()
                    .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            })
            .ok_or_else(|| GpuError::NoDevice(format!("{} has no compute queue", chosen.name)))?
            as u32;
        let timestamp_valid_bits = families[queue_family as usize].timestamp_valid_bits;

        // Properties.
        let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
        let mut driver = vk::PhysicalDeviceDriverProperties::default();
        let mut maint3 = vk::PhysicalDeviceMaintenance3Properties::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut subgroup)
            .push_next(&mut driver)
            .push_next(&mut maint3);
        instance.get_physical_device_properties2(physical, &mut props2);
        let props = props2.properties;
        let limits = props.limits;

        // Features: query what is there, enable what we need.
        let mut have12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut have2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut have12);
        instance.get_physical_device_features2(physical, &mut have2);
        let have10 = have2.features;
        let features10 = vk::PhysicalDeviceFeatures::default()
            .shader_int64(true)
            .shader_int16(have10.shader_int16 == vk::TRUE);
        let mut features12 = vk::PhysicalDeviceVulkan12Features::default()
            .buffer_device_address(true)
            .storage_buffer8_bit_access(have12.storage_buffer8_bit_access == vk::TRUE)
            .shader_int8(have12.shader_int8 == vk::TRUE)
            .scalar_block_layout(have12.scalar_block_layout == vk::TRUE)
            .timeline_semaphore(have12.timeline_semaphore == vk::TRUE)
            .host_query_reset(have12.host_query_reset == vk::TRUE)
            .vulkan_memory_model(have12.vulkan_memory_model == vk::TRUE)
            .vulkan_memory_model_device_scope(have12.vulkan_memory_model_device_scope == vk::TRUE)
            .shader_buffer_int64_atomics(have12.shader_buffer_int64_atomics == vk::TRUE)
            .shader_shared_int64_atomics(have12.shader_shared_int64_atomics == vk::TRUE);
        let mut features2 = vk::PhysicalDeviceFeatures2::default()
            .features(features10)
            .push_next(&mut features12);

        let priorities = [1.0f32];
        let queue_infos = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(queue_family)
            .queue_priorities(&priorities)];
        let presentation = options.display.is_some();
        let device_exts = if presentation {
            vec![ash::khr::swapchain::NAME.as_ptr()]
        } else {
            Vec::new()
        };
        let device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_infos)
            .enabled_extension_names(&device_exts)
            .push_next(&mut features2);
        let device = instance
            .create_device(physical, &device_info, None)
            .map_err(vk_err("vkCreateDevice"))?;
        let queue = device.get_device_queue(queue_family, 0);

        let allocator = match Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device: physical,
            debug_settings: {
                let mut d = AllocatorDebugSettings::default();
                // Drop reports leaks itself (at error level) only when there are some.
                d.log_leaks_on_shutdown = false;
                d
            },
            buffer_device_address: true,
            allocation_sizes: AllocationSizes::default(),
        }) {
            Ok(a) => a,
            Err(e) => {
                device.destroy_device(None);
                return Err(GpuError::Allocation {
                    name: "allocator".into(),
                    message: e.to_string(),
                });
            }
        };

        let info = DeviceInfo {
            name: chosen.name.clone(),
            device_type: chosen.type_name.to_string(),
            driver_name: cstr_field(driver.driver_name_as_c_str()),
            driver_info: cstr_field(driver.driver_info_as_c_str()),
            api_version: (
                vk::api_version_major(props.api_version),
                vk::api_version_minor(props.api_version),
                vk::api_version_patch(props.api_version),
            ),
            subgroup_size: subgroup.subgroup_size,
            max_storage_buffer_range: limits.max_storage_buffer_range,
            max_memory_allocation_size: maint3.max_memory_allocation_size,
            timestamp_period: limits.timestamp_period,
            timestamp_valid_bits,
            max_compute_workgroup_size: limits.max_compute_work_group_size,
            max_compute_workgroup_invocations: limits.max_compute_work_group_invocations,
            max_compute_workgroup_count: limits.max_compute_work_group_count,
            max_push_constants_size: limits.max_push_constants_size,
            storage_buffer_8bit: have12.storage_buffer8_bit_access == vk::TRUE,
            scalar_block_layout: have12.scalar_block_layout == vk::TRUE,
            timeline_semaphores: have12.timeline_semaphore == vk::TRUE,
        };
        log::info!(
            "GPU: {} ({}), driver {} {}, Vulkan {}.{}.{}, subgroup size {}, validation {}",
            info.name,
            info.device_type,
            info.driver_name,
            info.driver_info,
            info.api_version.0,
            info.api_version.1,
            info.api_version.2,
            info.subgroup_size,
            if validation { "on" } else { "off" }
        );
        log::info!(
            "GPU limits: max storage buffer range {} MiB, max allocation {} MiB, timestamp period {} ns \
             ({} valid bits), max workgroup size {:?}",
            info.max_storage_buffer_range >> 20,
            info.max_memory_allocation_size >> 20,
            info.timestamp_period,
            info.timestamp_valid_bits,
            info.max_compute_workgroup_size
        );

        let debug_device = debug_instance
            .as_ref()
            .map(|_| ash::ext::debug_utils::Device::new(&instance, &device));
        guard.instance = None; // ownership moves into the context
        let ctx = GpuContext {
            entry,
            instance,
            debug_instance,
            messenger,
            messenger_state,
            device,
            debug_device,
            queue: Mutex::new(queue),
            queue_family,
            allocator: ManuallyDrop::new(Mutex::new(allocator)),
            info,
            validation,
            presentation,
            physical,
        };
        ctx.set_name(queue, "main queue");
        Ok(Arc::new(ctx))
    }

    unsafe fn supports_required(instance: &ash::Instance, pd: vk::PhysicalDevice) -> bool {
        let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f12);
        instance.get_physical_device_features2(pd, &mut f2);
        let has_compute = instance
            .get_physical_device_queue_family_properties(pd)
            .iter()
            .any(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE));
        f2.features.shader_int64 == vk::TRUE && f12.buffer_device_address == vk::TRUE && has_compute
    }

    /// The chosen device and its limits.
    pub fn info(&self) -> &DeviceInfo {
        &self.info
    }

    /// Whether the validation layer is active.
    pub fn validation_enabled(&self) -> bool {
        self.validation
    }

    /// Number of warning and error messages reported by the validation layer / loader so far.
    pub fn validation_errors(&self) -> usize {
        self.messenger_state.problems.load(Ordering::SeqCst)
    }

    /// Number of live gpu-allocator allocations (0 once every buffer and image is dropped).
    pub fn live_allocations(&self) -> usize {
        self.allocator().generate_report().allocations.len()
    }

    /// Bytes currently allocated through gpu-allocator.
    pub fn allocated_bytes(&self) -> u64 {
        self.allocator().generate_report().total_allocated_bytes
    }

    /// Waits until the device has finished all submitted work.
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        let _q = self.queue();
        // SAFETY: the queue lock is held, so no submission races with the wait.
        unsafe { self.device.device_wait_idle() }.map_err(vk_err("vkDeviceWaitIdle"))
    }

    pub(crate) fn allocator(&self) -> MutexGuard<'_, Allocator> {
        self.allocator.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn queue(&self) -> MutexGuard<'_, vk::Queue> {
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Names a Vulkan object for validation messages, RenderDoc and Nsight (no-op without debug utils).
    pub(crate) fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Some(du) = &self.debug_device else {
            return;
        };
        let Ok(cname) = CString::new(name.replace('\0', " ")) else {
            return;
        };
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(handle)
            .object_name(&cname);
        // SAFETY: the handle belongs to this device; failure to name is harmless.
        let _ = unsafe { du.set_debug_utils_object_name(&info) };
    }
}

impl Drop for GpuContext {
    fn drop(&mut self) {
        // SAFETY: every resource holds an Arc to the context, so none is alive any more; wait for
        // the GPU, then destroy in reverse creation order, each object exactly once.
        unsafe {
            let _ = self.device.device_wait_idle();
            {
                let allocator = self.allocator();
                let report = allocator.generate_report();
                if !report.allocations.is_empty() {
                    allocator.report_memory_leaks(log::Level::Error);
                }
            }
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some(di) = &self.debug_instance {
                di.destroy_debug_utils_messenger(self.messenger, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

/// Destroys a half-built instance when device creation fails.
struct InstanceGuard {
    instance: Option<ash::Instance>,
    debug: Option<ash::ext::debug_utils::Instance>,
    messenger: vk::DebugUtilsMessengerEXT,
}

impl Drop for InstanceGuard {
    fn drop(&mut self) {
        if let Some(instance) = self.instance.take() {
            // SAFETY: nothing else owns these handles on the error path.
            unsafe {
                if let Some(d) = &self.debug {
                    d.destroy_debug_utils_messenger(self.messenger, None);
                }
                instance.destroy_instance(None);
            }
        }
    }
}
