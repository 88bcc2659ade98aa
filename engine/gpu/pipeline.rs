//! Compute pipelines from embedded SPIR-V, with specialization and push constants.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use ash::vk;

use super::release::Garbage;
use super::{vk_err, GpuContext, GpuError};

/// How to build a [`ComputePipeline`].
#[derive(Clone, Debug)]
pub struct ComputePipelineDesc<'a> {
    /// Debug name of the pipeline (also used in errors).
    pub name: &'a str,
    /// SPIR-V words, e.g. `voxdag::gpu::shaders::TEST_FILL`.
    pub spirv: &'a [u32],
    /// Specialization constants: entry `i` sets `layout(constant_id = i)` (u32/int/bool-sized).
    pub spec_constants: &'a [u32],
    /// Size of the push-constant block in bytes (0 = none; at most `maxPushConstantsSize`).
    pub push_constant_size: u32,
    /// What the shader binds at `set = 0`: entry `i` is binding `i` (empty: no descriptor set).
    pub bindings: &'a [BindingKind],
}

/// Most bindings of one kind a pipeline may have (the recorders' descriptor pools are sized for
/// it).
pub(crate) const MAX_BINDINGS_PER_KIND: u32 = 5;

/// A descriptor a pipeline binds (one per binding of set 0; the resource is given per dispatch,
/// `Commands::dispatch`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    /// An RGBA8 storage image (`image2D`), an [`super::Image`].
    StorageImage,
    /// A uniform texel buffer (`usamplerBuffer`), a [`super::TexelBuffer`].
    TexelBuffer,
}

impl BindingKind {
    /// Every kind.
    pub(crate) const ALL: [BindingKind; 2] = [BindingKind::StorageImage, BindingKind::TexelBuffer];

    pub(crate) fn descriptor_type(self) -> vk::DescriptorType {
        match self {
            BindingKind::StorageImage => vk::DescriptorType::STORAGE_IMAGE,
            BindingKind::TexelBuffer => vk::DescriptorType::UNIFORM_TEXEL_BUFFER,
        }
    }
}

/// The value in `slot` (pipelines made on first use), made by `make` unless it is there. Two
/// threads may both make it: the first one stored is kept and the other dropped, which is right
/// for anything made from the same description.
pub fn made_once<T>(
    slot: &OnceLock<T>,
    make: impl FnOnce() -> Result<T, GpuError>,
) -> Result<&T, GpuError> {
    if let Some(made) = slot.get() {
        return Ok(made);
    }
    let made = make()?;
    Ok(slot.get_or_init(|| made))
}

/// A compute pipeline and its layout; released on drop once the GPU is done with it.
pub struct ComputePipeline {
    pub(crate) raw: vk::Pipeline,
    pub(crate) layout: vk::PipelineLayout,
    pub(crate) set_layout: Option<vk::DescriptorSetLayout>,
    pub(crate) push_constant_size: u32,
    pub(crate) bindings: Vec<BindingKind>,
    /// Whether a dispatch of it was recorded: a driver may compile the native code at the first
    /// one ([`GpuContext::first_dispatches`]).
    dispatched: AtomicBool,
    name: String,
    ctx: Arc<GpuContext>,
}

impl std::fmt::Debug for ComputePipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ComputePipeline")
            .field("name", &self.name)
            .finish()
    }
}

impl ComputePipeline {
    /// Debug name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// What the pipeline binds at set 0, by binding.
    pub fn bindings(&self) -> &[BindingKind] {
        &self.bindings
    }

    /// Notes a recorded dispatch; true for the pipeline's first.
    pub(crate) fn note_dispatch(&self) -> bool {
        !self.dispatched.load(Ordering::Relaxed) && !self.dispatched.swap(true, Ordering::Relaxed)
    }
}

impl Drop for ComputePipeline {
    fn drop(&mut self) {
        self.ctx
            .defer(Garbage::Pipeline(self.raw, self.layout, self.set_layout));
    }
}

impl GpuContext {
    /// Builds a compute pipeline (entry point `main`).
    pub fn create_compute_pipeline(
        self: &Arc<Self>,
        desc: &ComputePipelineDesc<'_>,
    ) -> Result<ComputePipeline, GpuError> {
        let name = desc.name;
        if desc.spirv.len() < 5 || desc.spirv[0] != 0x0723_0203 {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{name}': not a SPIR-V module"
            )));
        }
        if desc.push_constant_size > self.info().max_push_constants_size
            || !desc.push_constant_size.is_multiple_of(4)
        {
            return Err(GpuError::InvalidArgument(format!(
                "pipeline '{name}': push constant size {} must be a multiple of 4 and at most {}",
                desc.push_constant_size,
                self.info().max_push_constants_size
            )));
        }
        for kind in BindingKind::ALL {
            let n = desc.bindings.iter().filter(|&&k| k == kind).count();
            if n > MAX_BINDINGS_PER_KIND as usize {
                return Err(GpuError::InvalidArgument(format!(
                    "pipeline '{name}': {n} bindings of kind {kind:?}, at most \
                     {MAX_BINDINGS_PER_KIND}"
                )));
            }
        }
        let device = &self.device;
        // SAFETY: valid create infos; on error everything created so far is destroyed.
        unsafe {
            let module = device
                .create_shader_module(
                    &vk::ShaderModuleCreateInfo::default().code(desc.spirv),
                    None,
                )
                .map_err(vk_err("vkCreateShaderModule"))?;
            let set_layout = if !desc.bindings.is_empty() {
                let bindings: Vec<vk::DescriptorSetLayoutBinding> = (desc.bindings.iter())
                    .enumerate()
                    .map(|(i, kind)| {
                        vk::DescriptorSetLayoutBinding::default()
                            .binding(i as u32)
                            .descriptor_type(kind.descriptor_type())
                            .descriptor_count(1)
                            .stage_flags(vk::ShaderStageFlags::COMPUTE)
                    })
                    .collect();
                match device.create_descriptor_set_layout(
                    &vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings),
                    None,
                ) {
                    Ok(l) => Some(l),
                    Err(e) => {
                        device.destroy_shader_module(module, None);
                        return Err(vk_err("vkCreateDescriptorSetLayout")(e));
                    }
                }
            } else {
                None
            };
            let set_layouts: Vec<vk::DescriptorSetLayout> = set_layout.into_iter().collect();
            let ranges = [vk::PushConstantRange {
                stage_flags: vk::ShaderStageFlags::COMPUTE,
                offset: 0,
                size: desc.push_constant_size,
            }];
            let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
            if desc.push_constant_size > 0 {
                layout_info = layout_info.push_constant_ranges(&ranges);
            }
            let cleanup = |module, set_layout: Option<vk::DescriptorSetLayout>| {
                device.destroy_shader_module(module, None);
                if let Some(s) = set_layout {
                    device.destroy_descriptor_set_layout(s, None);
                }
            };
            let layout = match device.create_pipeline_layout(&layout_info, None) {
                Ok(l) => l,
                Err(e) => {
                    cleanup(module, set_layout);
                    return Err(vk_err("vkCreatePipelineLayout")(e));
                }
            };
            let entries: Vec<vk::SpecializationMapEntry> = (0..desc.spec_constants.len())
                .map(|i| vk::SpecializationMapEntry {
                    constant_id: i as u32,
                    offset: (i * 4) as u32,
                    size: 4,
                })
                .collect();
            let spec_data: &[u8] = bytemuck::cast_slice(desc.spec_constants);
            let spec = vk::SpecializationInfo::default()
                .map_entries(&entries)
                .data(spec_data);
            let entry = c"main";
            let mut stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(entry);
            if !entries.is_empty() {
                stage = stage.specialization_info(&spec);
            }
            let info = vk::ComputePipelineCreateInfo::default()
                .stage(stage)
                .layout(layout);
            let result = device.create_compute_pipelines(vk::PipelineCache::null(), &[info], None);
            device.destroy_shader_module(module, None);
            let raw = match result {
                Ok(p) => p[0],
                Err((_, e)) => {
                    device.destroy_pipeline_layout(layout, None);
                    if let Some(s) = set_layout {
                        device.destroy_descriptor_set_layout(s, None);
                    }
                    log::error!("creating pipeline '{name}' failed: {e:?}");
                    return Err(vk_err("vkCreateComputePipelines")(e));
                }
            };
            self.count_pipeline();
            self.set_name(raw, name);
            self.set_name(layout, &format!("{name} (layout)"));
            if let Some(s) = set_layout {
                self.set_name(s, &format!("{name} (set layout)"));
            }
            Ok(ComputePipeline {
                raw,
                layout,
                set_layout,
                push_constant_size: desc.push_constant_size,
                bindings: desc.bindings.to_vec(),
                dispatched: AtomicBool::new(false),
                name: name.to_string(),
                ctx: Arc::clone(self),
            })
        }
    }
}
