//! Instance, device selection (with a check of every feature the shaders use), logical device,
//! allocator, validation messenger, the queue's timeline semaphore, the deferred-release queue,
//! the staging rings and submission statistics.

use std::ffi::{c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use gpu_allocator::{AllocationSizes, AllocatorDebugSettings, MemoryLocation};

use super::release::{FreeBuffers, Garbage, KeptBuffer, Recorder};
use super::ring::{Ring, RingAlloc, RingKind};
use super::{vk_err, ComputePipeline, GpuError, MemLocation};

/// Bytes of each staging ring (upload and readback).
const RING_BYTES: u64 = 4 << 20;
/// Name prefix of the context's own allocations (the rings), left out of
/// [`GpuContext::live_allocations`] and [`GpuContext::allocated_bytes`].
const INTERNAL_PREFIX: &str = "voxdag internal:";
/// Recorders kept for reuse; more are destroyed when released.
const MAX_FREE_RECORDERS: usize = 32;

/// Every device feature voxdag requires, by its Vulkan name: the shaders'
/// `#extension`s (`GL_EXT_buffer_reference` -> `bufferDeviceAddress`,
/// `GL_EXT_shader_explicit_arithmetic_types_int64` -> `shaderInt64`,
/// `GL_EXT_shader_atomic_int64` -> `shaderBufferInt64Atomics`, `GL_KHR_shader_subgroup_*` ->
/// the subgroup operations in compute shaders) and the host's (`timelineSemaphore`). A device
/// missing any is refused with [`GpuError::Unsupported`].
pub const REQUIRED_FEATURES: &[&str] = &[
    "Vulkan 1.2",
    "compute queue",
    "shaderInt64",
    "bufferDeviceAddress",
    "shaderBufferInt64Atomics",
    "timelineSemaphore",
    "subgroupComputeStage",
    "VK_SUBGROUP_FEATURE_BASIC_BIT",
    "VK_SUBGROUP_FEATURE_VOTE_BIT",
    "VK_SUBGROUP_FEATURE_BALLOT_BIT",
    "VK_SUBGROUP_FEATURE_ARITHMETIC_BIT",
];

/// Options for [`GpuContext::new`].
#[derive(Clone, Debug)]
pub struct GpuOptions {
    /// Enable `VK_LAYER_KHRONOS_validation` when installed (default: env `VOXDAG_VALIDATION`,
    /// else on in debug builds and off in release builds).
    pub validation: bool,
    /// Pick the first device whose name contains this (case-insensitive) substring
    /// (default: env `VOXDAG_DEVICE`).
    pub device: Option<String>,
    /// With validation: also enable synchronization validation (default: env
    /// `VOXDAG_SYNC_VALIDATION`, else on).
    pub sync_validation: bool,
    /// Test-only: treat these [`REQUIRED_FEATURES`] as missing on every device, to prove the
    /// refusal (default: env `VOXDAG_MASK_FEATURES`, comma-separated; normally empty).
    pub mask_features: Vec<String>,
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
        let sync_validation = !matches!(
            std::env::var("VOXDAG_SYNC_VALIDATION").ok().as_deref(),
            Some("0") | Some("false") | Some("off")
        );
        let mask_features = std::env::var("VOXDAG_MASK_FEATURES")
            .map(|s| {
                s.split(',')
                    .map(|f| f.trim().to_string())
                    .filter(|f| !f.is_empty())
                    .collect()
            })
            .unwrap_or_default();
        GpuOptions {
            validation,
            device,
            sync_validation,
            mask_features,
            display: None,
        }
    }
}

/// What the chosen device is and the limits that matter to voxdag.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// Device name, e.g. `llvmpipe (LLVM 15.0.6, 256 bits)`.
    pub name: String,
    /// Device type.
    pub device_type: DeviceType,
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
    /// `maxTexelBufferElements`: most texels a texel buffer view may hold.
    pub max_texel_buffer_elements: u32,
    /// Whether `storageBuffer8BitAccess` was enabled.
    pub storage_buffer_8bit: bool,
    /// Whether `scalarBlockLayout` was enabled.
    pub scalar_block_layout: bool,
    /// Whether timeline semaphores were enabled.
    pub timeline_semaphores: bool,
}

/// Kind of physical device.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DeviceType {
    /// A discrete GPU.
    Discrete,
    /// A GPU integrated with the CPU.
    Integrated,
    /// A virtualised GPU.
    Virtual,
    /// A CPU implementation (lavapipe, SwiftShader).
    Cpu,
    /// Anything else.
    Other,
}

impl DeviceType {
    fn from_vk(t: vk::PhysicalDeviceType) -> DeviceType {
        match t {
            vk::PhysicalDeviceType::DISCRETE_GPU => DeviceType::Discrete,
            vk::PhysicalDeviceType::INTEGRATED_GPU => DeviceType::Integrated,
            vk::PhysicalDeviceType::VIRTUAL_GPU => DeviceType::Virtual,
            vk::PhysicalDeviceType::CPU => DeviceType::Cpu,
            _ => DeviceType::Other,
        }
    }

    /// Preference when choosing a device (lower is better).
    fn rank(self) -> u32 {
        match self {
            DeviceType::Discrete => 0,
            DeviceType::Integrated => 1,
            DeviceType::Virtual => 2,
            DeviceType::Other => 3,
            DeviceType::Cpu => 4,
        }
    }
}

impl std::fmt::Display for DeviceType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            DeviceType::Discrete => "discrete",
            DeviceType::Integrated => "integrated",
            DeviceType::Virtual => "virtual",
            DeviceType::Cpu => "cpu",
            DeviceType::Other => "other",
        })
    }
}

/// Submissions and host waits so far (see [`GpuContext::stats`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuStats {
    /// Queue submissions (`vkQueueSubmit` calls).
    pub submissions: u64,
    /// Host synchronisation points: waits for a timeline value beyond every value waited for
    /// before (counted whether or not the GPU had already finished, so the count depends on the
    /// code path, not on timing).
    pub host_waits: u64,
}

impl GpuStats {
    /// What happened since `earlier`.
    pub fn since(self, earlier: GpuStats) -> GpuStats {
        GpuStats {
            submissions: self.submissions - earlier.submissions,
            host_waits: self.host_waits - earlier.host_waits,
        }
    }
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
    /// Family of `queue`; every command recorder's pool is created for it.
    pub(crate) queue_family: u32,
    allocator: ManuallyDrop<Mutex<Allocator>>,
    info: DeviceInfo,
    validation: bool,
    /// Whether the surface and swapchain extensions are enabled ([`GpuOptions::display`]).
    pub(crate) presentation: bool,
    /// The chosen physical device (surface queries).
    pub(crate) physical: vk::PhysicalDevice,
    /// The queue's timeline semaphore: submission `n` signals value `n`.
    timeline: vk::Semaphore,
    /// Value of the last submission (written with the queue locked).
    last_submitted: AtomicU64,
    /// Highest value known to be completed (a cache of the semaphore's counter).
    completed: AtomicU64,
    /// Garbage waiting for the GPU, with the timeline value it waits for.
    deferred: Mutex<Vec<(u64, Garbage)>>,
    /// Reset recorders ready for reuse.
    free_recorders: Mutex<Vec<Recorder>>,
    /// Dropped buffers of the reusable size classes whose last submission completed.
    free_buffers: Mutex<FreeBuffers>,
    upload_ring: Mutex<Ring>,
    readback_ring: Mutex<Ring>,
    submissions: AtomicU64,
    host_waits: AtomicU64,
    pipelines_created: AtomicU64,
    first_dispatches: AtomicU64,
    /// Highest value the host has waited for (host waits count values beyond it).
    waited: AtomicU64,
}

impl std::fmt::Debug for GpuContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuContext")
            .field("device", &self.info().name)
            .finish()
    }
}

/// A physical device candidate during selection.
struct Candidate {
    physical: vk::PhysicalDevice,
    name: String,
    device_type: DeviceType,
    /// Required features it lacks (or that are masked), in [`REQUIRED_FEATURES`] order.
    missing: Vec<&'static str>,
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
        // Synchronization validation comes with the layer's VK_EXT_validation_features.
        let sync_validation = validation
            && options.sync_validation
            && entry
                .enumerate_instance_extension_properties(Some(validation_name))
                .map_err(vk_err("vkEnumerateInstanceExtensionProperties"))?
                .iter()
                .any(|e| {
                    e.extension_name_as_c_str().ok() == Some(ash::ext::validation_features::NAME)
                });
        let mut ext_ptrs: Vec<*const std::ffi::c_char> = Vec::new();
        if has_debug_utils {
            ext_ptrs.push(ash::ext::debug_utils::NAME.as_ptr());
        }
        if sync_validation {
            ext_ptrs.push(ash::ext::validation_features::NAME.as_ptr());
        }
        let enabled_checks = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut validation_features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enabled_checks);
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
        if sync_validation {
            instance_info = instance_info.push_next(&mut validation_features);
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
            candidates.push(Candidate {
                physical: pd,
                name: cstr_field(props.device_name_as_c_str()),
                device_type: DeviceType::from_vk(props.device_type),
                missing: Self::missing_features(&instance, pd, &options.mask_features),
            });
        }
        let listing = candidates
            .iter()
            .map(|c| format!("\"{}\" ({})", c.name, c.device_type))
            .collect::<Vec<_>>()
            .join(", ");
        candidates.sort_by_key(|c| c.device_type.rank());
        let unsupported = |c: &Candidate| GpuError::Unsupported {
            device: c.name.clone(),
            feature: c.missing[0].to_string(),
        };
        let chosen = match &options.device {
            Some(wanted) => {
                let w = wanted.to_lowercase();
                let matching: Vec<&Candidate> = candidates
                    .iter()
                    .filter(|c| c.name.to_lowercase().contains(&w))
                    .collect();
                match matching.iter().find(|c| c.missing.is_empty()) {
                    Some(c) => *c,
                    None => {
                        return Err(match matching.first() {
                            Some(c) => unsupported(c),
                            None => GpuError::DeviceNotFound {
                                wanted: wanted.clone(),
                                available: if listing.is_empty() {
                                    "none".into()
                                } else {
                                    listing.clone()
                                },
                            },
                        })
                    }
                }
            }
            None => match candidates.iter().find(|c| c.missing.is_empty()) {
                Some(c) => c,
                None => {
                    return Err(match candidates.first() {
                        Some(c) => unsupported(c),
                        None => GpuError::NoDevice("no Vulkan devices found".into()),
                    })
                }
            },
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
            .ok_or_else(|| GpuError::Unsupported {
                device: chosen.name.clone(),
                feature: "compute queue".into(),
            })? as u32;
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
            .timeline_semaphore(true)
            .host_query_reset(have12.host_query_reset == vk::TRUE)
            .vulkan_memory_model(have12.vulkan_memory_model == vk::TRUE)
            .vulkan_memory_model_device_scope(have12.vulkan_memory_model_device_scope == vk::TRUE)
            .shader_buffer_int64_atomics(true)
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
                return Err(GpuError::from_allocation("allocator", e));
            }
        };

        let info = DeviceInfo {
            name: chosen.name.clone(),
            device_type: chosen.device_type,
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
            max_texel_buffer_elements: limits.max_texel_buffer_elements,
            storage_buffer_8bit: have12.storage_buffer8_bit_access == vk::TRUE,
            scalar_block_layout: have12.scalar_block_layout == vk::TRUE,
            timeline_semaphores: true,
        };
        log::info!(
            "GPU: {} ({}), driver {} {}, Vulkan {}.{}.{}, subgroup size {}, validation {}{}",
            info.name,
            info.device_type,
            info.driver_name,
            info.driver_info,
            info.api_version.0,
            info.api_version.1,
            info.api_version.2,
            info.subgroup_size,
            if validation { "on" } else { "off" },
            if sync_validation {
                " (with synchronization validation)"
            } else {
                ""
            }
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
        let mut timeline_type = vk::SemaphoreTypeCreateInfo::default()
            .semaphore_type(vk::SemaphoreType::TIMELINE)
            .initial_value(0);
        let timeline = match device.create_semaphore(
            &vk::SemaphoreCreateInfo::default().push_next(&mut timeline_type),
            None,
        ) {
            Ok(t) => t,
            Err(e) => {
                drop(allocator);
                device.destroy_device(None);
                return Err(vk_err("vkCreateSemaphore")(e));
            }
        };
        let allocator = ManuallyDrop::new(Mutex::new(allocator));
        let ring = |name: &str, location| {
            Self::raw_buffer_with(&device, &allocator, name, RING_BYTES, location).map(
                |(raw, allocation, _)| Ring {
                    raw,
                    allocation: Some(allocation),
                    alloc: RingAlloc::new(RING_BYTES),
                },
            )
        };
        let rings = ring(
            &format!("{INTERNAL_PREFIX} upload ring"),
            MemoryLocation::CpuToGpu,
        )
        .and_then(|u| {
            ring(
                &format!("{INTERNAL_PREFIX} readback ring"),
                MemoryLocation::GpuToCpu,
            )
            .map(|r| (u, r))
        });
        let (upload_ring, readback_ring) = match rings {
            Ok(r) => r,
            Err(e) => {
                // Only the rings can have been allocated; the allocator frees its blocks.
                let mut allocator = allocator;
                ManuallyDrop::drop(&mut allocator);
                device.destroy_semaphore(timeline, None);
                device.destroy_device(None);
                return Err(e);
            }
        };
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
            allocator,
            info,
            validation,
            timeline,
            last_submitted: AtomicU64::new(0),
            completed: AtomicU64::new(0),
            deferred: Mutex::new(Vec::new()),
            free_recorders: Mutex::new(Vec::new()),
            free_buffers: Mutex::new(FreeBuffers::default()),
            upload_ring: Mutex::new(upload_ring),
            readback_ring: Mutex::new(readback_ring),
            submissions: AtomicU64::new(0),
            host_waits: AtomicU64::new(0),
            pipelines_created: AtomicU64::new(0),
            first_dispatches: AtomicU64::new(0),
            waited: AtomicU64::new(0),
            presentation,
            physical,
        };
        ctx.set_name(queue, "main queue");
        ctx.set_name(timeline, "main queue timeline");
        {
            let u = ctx.upload_ring();
            ctx.set_name(u.raw, "upload ring");
        }
        {
            let r = ctx.readback_ring();
            ctx.set_name(r.raw, "readback ring");
        }
        Ok(Arc::new(ctx))
    }

    /// The required features `pd` lacks (plus those masked by `mask`), in
    /// [`REQUIRED_FEATURES`] order.
    unsafe fn missing_features(
        instance: &ash::Instance,
        pd: vk::PhysicalDevice,
        mask: &[String],
    ) -> Vec<&'static str> {
        let props = instance.get_physical_device_properties(pd);
        let api12 = props.api_version >= vk::API_VERSION_1_2;
        let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
        if api12 {
            let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f12);
            instance.get_physical_device_features2(pd, &mut f2);
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut subgroup);
            instance.get_physical_device_properties2(pd, &mut p2);
        }
        let f10 = instance.get_physical_device_features(pd);
        let has_compute = instance
            .get_physical_device_queue_family_properties(pd)
            .iter()
            .any(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE));
        let ops = subgroup.supported_operations;
        let have = [
            api12,
            has_compute,
            f10.shader_int64 == vk::TRUE,
            f12.buffer_device_address == vk::TRUE,
            f12.shader_buffer_int64_atomics == vk::TRUE,
            f12.timeline_semaphore == vk::TRUE,
            subgroup
                .supported_stages
                .contains(vk::ShaderStageFlags::COMPUTE),
            ops.contains(vk::SubgroupFeatureFlags::BASIC),
            ops.contains(vk::SubgroupFeatureFlags::VOTE),
            ops.contains(vk::SubgroupFeatureFlags::BALLOT),
            ops.contains(vk::SubgroupFeatureFlags::ARITHMETIC),
        ];
        REQUIRED_FEATURES
            .iter()
            .zip(have)
            .filter(|(name, ok)| !ok || mask.iter().any(|m| m == **name))
            .map(|(name, _)| *name)
            .collect()
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

    /// Number of live gpu-allocator allocations of buffers and images (the context's own
    /// staging rings left out). Releases whatever the GPU has finished with first, so it is 0
    /// once every buffer and image is dropped and their last submission has completed (call
    /// [`GpuContext::wait_idle`] first to be sure of the latter).
    pub fn live_allocations(&self) -> usize {
        self.maintain();
        self.release_free_buffers();
        self.allocator()
            .generate_report()
            .allocations
            .iter()
            .filter(|a| !a.name.starts_with(INTERNAL_PREFIX))
            .count()
    }

    /// Bytes allocated through gpu-allocator for buffers and images (rings left out; releases
    /// finished garbage first, as [`GpuContext::live_allocations`]).
    pub fn allocated_bytes(&self) -> u64 {
        self.maintain();
        self.release_free_buffers();
        self.allocator()
            .generate_report()
            .allocations
            .iter()
            .filter(|a| !a.name.starts_with(INTERNAL_PREFIX))
            .map(|a| a.size)
            .sum()
    }

    /// Objects dropped by their owners and still waiting for the GPU (deferred release queue).
    pub fn pending_releases(&self) -> usize {
        self.maintain();
        self.deferred().len()
    }

    /// Waits until the GPU has finished every submission, then releases all deferred garbage.
    pub fn wait_idle(&self) -> Result<(), GpuError> {
        self.wait_for(self.last_submitted())?;
        {
            let _q = self.queue();
            // SAFETY: the queue lock is held, so no submission races with the wait.
            unsafe { self.device.device_wait_idle() }.map_err(vk_err("vkDeviceWaitIdle"))?;
        }
        self.maintain();
        Ok(())
    }

    /// Timeline value of the last submission (0 before the first).
    pub fn last_submitted(&self) -> u64 {
        self.last_submitted.load(Ordering::Acquire)
    }

    /// Highest timeline value the GPU has completed (asks the semaphore).
    pub fn completed_value(&self) -> Result<u64, GpuError> {
        // SAFETY: the semaphore belongs to this device.
        let v = unsafe { self.device.get_semaphore_counter_value(self.timeline) }
            .map_err(vk_err("vkGetSemaphoreCounterValue"))?;
        self.completed.fetch_max(v, Ordering::AcqRel);
        Ok(v)
    }

    /// Blocks until the GPU has completed submission `value`, then releases the garbage it
    /// held. Counted in [`GpuStats::host_waits`] when `value` is beyond every value waited for
    /// before.
    pub fn wait_for(&self, value: u64) -> Result<(), GpuError> {
        if value > self.last_submitted() {
            return Err(GpuError::InvalidArgument(format!(
                "wait for timeline value {value}, but only {} were submitted",
                self.last_submitted()
            )));
        }
        // A synchronisation point: the first time the host needs this value (deterministic,
        // whether or not the GPU happens to be done already).
        if value > 0 && self.waited.fetch_max(value, Ordering::AcqRel) < value {
            self.host_waits.fetch_add(1, Ordering::Relaxed);
        }
        if value <= self.completed.load(Ordering::Acquire) {
            return Ok(());
        }
        let semaphores = [self.timeline];
        let values = [value];
        let info = vk::SemaphoreWaitInfo::default()
            .semaphores(&semaphores)
            .values(&values);
        // SAFETY: waiting on our own timeline semaphore for a submitted value.
        unsafe { self.device.wait_semaphores(&info, u64::MAX) }
            .map_err(vk_err("vkWaitSemaphores"))?;
        self.completed.fetch_max(value, Ordering::AcqRel);
        self.maintain();
        Ok(())
    }

    /// Submissions and host waits so far.
    pub fn stats(&self) -> GpuStats {
        GpuStats {
            submissions: self.submissions.load(Ordering::Relaxed),
            host_waits: self.host_waits.load(Ordering::Relaxed),
        }
    }

    /// Compute pipelines created so far: what work made at its first use instead of before
    /// shows up here (lavapipe turns each into NIR here and compiles it at its first dispatch:
    /// [`GpuContext::first_dispatches`]).
    pub fn pipelines_created(&self) -> u64 {
        self.pipelines_created.load(Ordering::Relaxed)
    }

    /// Counts a created compute pipeline.
    pub(crate) fn count_pipeline(&self) {
        self.pipelines_created.fetch_add(1, Ordering::Relaxed);
    }

    /// Recorded dispatches that were their pipeline's first (warm-ups of
    /// [`crate::gpu::Commands::warm`] included). A driver may compile a pipeline's native code
    /// there rather than at its creation: lavapipe's llvmpipe does (a pipeline keeps its NIR,
    /// the first dispatch compiles it, or loads it from Mesa's disk cache in ~0.5-1 ms), so
    /// what work makes ready before it runs shows up here as well as in
    /// [`GpuContext::pipelines_created`].
    pub fn first_dispatches(&self) -> u64 {
        self.first_dispatches.load(Ordering::Relaxed)
    }

    /// Counts a dispatch of `pipeline` if it is its first.
    pub(crate) fn note_dispatch(&self, pipeline: &ComputePipeline) {
        if pipeline.note_dispatch() {
            self.first_dispatches.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The timeline semaphore submissions signal.
    pub(crate) fn timeline(&self) -> vk::Semaphore {
        self.timeline
    }

    /// Submits `submit` (whose timeline signal value the closure fills in) as the next timeline
    /// value; returns it. The queue stays locked across the value choice and the submit, so
    /// values signal in submission order.
    pub(crate) fn submit_next(
        &self,
        submit: impl FnOnce(vk::Queue, u64) -> Result<(), GpuError>,
    ) -> Result<u64, GpuError> {
        let queue = self.queue();
        let value = self.last_submitted.load(Ordering::Acquire) + 1;
        submit(*queue, value)?;
        self.last_submitted.store(value, Ordering::Release);
        self.submissions.fetch_add(1, Ordering::Relaxed);
        drop(queue);
        Ok(value)
    }

    /// Queues `garbage` until the last submission so far has completed (or destroys it now if
    /// it has).
    pub(crate) fn defer(&self, garbage: Garbage) {
        let value = self.last_submitted();
        if value <= self.completed.load(Ordering::Acquire) {
            self.destroy(garbage);
        } else {
            self.deferred().push((value, garbage));
        }
    }

    /// Queues `garbage` until timeline value `value` has completed.
    pub(crate) fn defer_until(&self, value: u64, garbage: Garbage) {
        if value <= self.completed.load(Ordering::Acquire) {
            self.destroy(garbage);
        } else {
            self.deferred().push((value, garbage));
        }
    }

    /// Releases every deferred object whose submission has completed (called on each begin,
    /// submit and wait).
    pub(crate) fn maintain(&self) {
        let done = self
            .completed_value()
            .unwrap_or_else(|_| self.completed.load(Ordering::Acquire));
        let ready: Vec<Garbage> = {
            let mut deferred = self.deferred();
            if deferred.iter().all(|(v, _)| *v > done) {
                return;
            }
            let (ready, keep): (Vec<_>, Vec<_>) = deferred.drain(..).partition(|(v, _)| *v <= done);
            *deferred = keep;
            ready.into_iter().map(|(_, g)| g).collect()
        };
        for g in ready {
            self.destroy(g);
        }
    }

    fn deferred(&self) -> MutexGuard<'_, Vec<(u64, Garbage)>> {
        self.deferred.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Destroys (or recycles) one object the GPU no longer uses.
    fn destroy(&self, garbage: Garbage) {
        let device = &self.device;
        // SAFETY: the GPU has passed the last submission that could use the object, which is
        // owned by the garbage entry alone; each is destroyed exactly once.
        unsafe {
            match garbage {
                Garbage::Buffer(raw, allocation, recyclable) => {
                    let rejected = match recyclable {
                        Some(r) => self.free_buffers().keep(raw, allocation, r),
                        None => Some((raw, allocation)),
                    };
                    if let Some((raw, allocation)) = rejected {
                        self.destroy_buffer(raw, allocation);
                    }
                }
                Garbage::BufferView(view) => device.destroy_buffer_view(view, None),
                Garbage::Image(raw, view, allocation) => {
                    device.destroy_image_view(view, None);
                    device.destroy_image(raw, None);
                    if let Err(e) = self.allocator().free(allocation) {
                        log::error!("freeing an image: {e}");
                    }
                }
                Garbage::Pipeline(raw, layout, set_layout) => {
                    device.destroy_pipeline(raw, None);
                    device.destroy_pipeline_layout(layout, None);
                    if let Some(s) = set_layout {
                        device.destroy_descriptor_set_layout(s, None);
                    }
                }
                Garbage::QueryPool(pool) => device.destroy_query_pool(pool, None),
                Garbage::Recorder(recorder) => self.recycle(recorder),
                Garbage::RingRegion(kind, id) => match kind {
                    RingKind::Upload => self.upload_ring().alloc.free(id),
                    RingKind::Readback => self.readback_ring().alloc.free(id),
                },
            }
        }
    }

    fn destroy_buffer(&self, raw: vk::Buffer, allocation: gpu_allocator::vulkan::Allocation) {
        // SAFETY: the GPU no longer uses the buffer, owned by the caller alone.
        unsafe { self.device.destroy_buffer(raw, None) };
        if let Err(e) = self.allocator().free(allocation) {
            log::error!("freeing a buffer: {e}");
        }
    }

    fn free_buffers(&self) -> MutexGuard<'_, FreeBuffers> {
        self.free_buffers.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// A dropped buffer of size class `class` in `location` whose last use has completed: its
    /// Vulkan buffer, allocation and device address. When none is kept, releases what has
    /// completed and looks again (without that, the 1 500-edit teapot replay ran 8-25 % slower:
    /// fewer buffers came back in time); not on every call, since an edit makes hundreds of
    /// small buffers and each release pass asks the timeline and walks the deferred list.
    pub(crate) fn reuse_buffer(&self, class: u64, location: MemLocation) -> Option<KeptBuffer> {
        if let Some(kept) = self.free_buffers().take(class, location) {
            return Some(kept);
        }
        self.maintain();
        self.free_buffers().take(class, location)
    }

    /// Destroys every kept free buffer (their memory goes back to the allocator).
    fn release_free_buffers(&self) {
        let all = self.free_buffers().drain();
        for (raw, allocation) in all {
            self.destroy_buffer(raw, allocation);
        }
    }

    /// A reset recorder from the free list, or a new one.
    pub(crate) fn acquire_recorder(&self) -> Result<Recorder, GpuError> {
        if let Some(r) = self.free_recorders().pop() {
            return Ok(r);
        }
        // SAFETY: a new pool and its command buffer, owned by the returned recorder alone.
        unsafe {
            let pool = self
                .device
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(self.queue_family)
                        .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                    None,
                )
                .map_err(vk_err("vkCreateCommandPool"))?;
            let buffer = match self.device.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            ) {
                Ok(b) => b[0],
                Err(e) => {
                    self.device.destroy_command_pool(pool, None);
                    return Err(vk_err("vkAllocateCommandBuffers")(e));
                }
            };
            Ok(Recorder {
                pool,
                buffer,
                descriptor_pools: Vec::new(),
                current_pool: 0,
                current_sets: 0,
            })
        }
    }

    /// Resets a recorder whose submission completed (or that was never submitted) and keeps it
    /// for reuse; beyond [`MAX_FREE_RECORDERS`] it is destroyed.
    pub(crate) fn recycle(&self, mut recorder: Recorder) {
        let device = &self.device;
        // SAFETY: nothing uses the recorder any more (its submission completed, or it was never
        // submitted); resetting the pool returns its command buffer to the initial state.
        unsafe {
            let ok = device
                .reset_command_pool(recorder.pool, vk::CommandPoolResetFlags::empty())
                .is_ok()
                && recorder.descriptor_pools.iter().all(|&p| {
                    device
                        .reset_descriptor_pool(p, vk::DescriptorPoolResetFlags::empty())
                        .is_ok()
                });
            recorder.current_pool = 0;
            recorder.current_sets = 0;
            let mut free = self.free_recorders();
            if ok && free.len() < MAX_FREE_RECORDERS {
                free.push(recorder);
            } else {
                drop(free);
                Self::destroy_recorder(device, recorder);
            }
        }
    }

    unsafe fn destroy_recorder(device: &ash::Device, recorder: Recorder) {
        for p in recorder.descriptor_pools {
            device.destroy_descriptor_pool(p, None);
        }
        device.destroy_command_pool(recorder.pool, None);
    }

    fn free_recorders(&self) -> MutexGuard<'_, Vec<Recorder>> {
        self.free_recorders
            .lock()
            .unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn upload_ring(&self) -> MutexGuard<'_, Ring> {
        self.upload_ring.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub(crate) fn readback_ring(&self) -> MutexGuard<'_, Ring> {
        self.readback_ring.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Creates a buffer with memory from the context's allocator; returns it, its allocation and
    /// its device address.
    pub(crate) fn raw_buffer(
        &self,
        name: &str,
        size: u64,
        location: MemoryLocation,
    ) -> Result<(vk::Buffer, gpu_allocator::vulkan::Allocation, u64), GpuError> {
        Self::raw_buffer_with(&self.device, &self.allocator, name, size, location)
    }

    /// Creates a buffer and binds memory from `allocator` (before the context exists, for the
    /// rings, and for every [`super::Buffer`]); returns it, its allocation and its address.
    pub(crate) fn raw_buffer_with(
        device: &ash::Device,
        allocator: &Mutex<Allocator>,
        name: &str,
        size: u64,
        location: MemoryLocation,
    ) -> Result<(vk::Buffer, gpu_allocator::vulkan::Allocation, u64), GpuError> {
        use gpu_allocator::vulkan::{AllocationCreateDesc, AllocationScheme};
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_SRC
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
            | vk::BufferUsageFlags::INDIRECT_BUFFER
            | vk::BufferUsageFlags::UNIFORM_TEXEL_BUFFER;
        let info = vk::BufferCreateInfo::default()
            .size(size)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        let lock = || allocator.lock().unwrap_or_else(|p| p.into_inner());
        // SAFETY: valid create info on our device; every error path destroys the buffer.
        unsafe {
            let raw = device
                .create_buffer(&info, None)
                .map_err(vk_err("vkCreateBuffer"))?;
            let requirements = device.get_buffer_memory_requirements(raw);
            let allocation = match lock().allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            }) {
                Ok(a) => a,
                Err(e) => {
                    device.destroy_buffer(raw, None);
                    return Err(GpuError::from_allocation(name, e));
                }
            };
            if let Err(e) = device.bind_buffer_memory(raw, allocation.memory(), allocation.offset())
            {
                device.destroy_buffer(raw, None);
                let _ = lock().free(allocation);
                return Err(vk_err("vkBindBufferMemory")(e));
            }
            let address = device
                .get_buffer_device_address(&vk::BufferDeviceAddressInfo::default().buffer(raw));
            Ok((raw, allocation, address))
        }
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
            self.completed.store(u64::MAX, Ordering::Release);
            let garbage: Vec<Garbage> = self.deferred().drain(..).map(|(_, g)| g).collect();
            for g in garbage {
                self.destroy(g);
            }
            for r in self.free_recorders().drain(..) {
                Self::destroy_recorder(&self.device, r);
            }
            self.release_free_buffers();
            for ring in [&self.upload_ring, &self.readback_ring] {
                let mut ring = ring.lock().unwrap_or_else(|p| p.into_inner());
                self.device.destroy_buffer(ring.raw, None);
                if let Some(a) = ring.allocation.take() {
                    let _ = self.allocator().free(a);
                }
            }
            self.device.destroy_semaphore(self.timeline, None);
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
