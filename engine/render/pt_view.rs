//! Showing a progressive path-traced render in a window (the editor's path-tracing mode):
//! `render/accum_display.comp` turns a [`PtTarget`]'s accumulation into an sRGB image (mean
//! radiance, brush preview tint on the first hit) and copies its first hits to a host-visible
//! buffer. [`display_cpu`] is its CPU twin ([`PtImage::to_rgba8`] plus the tint).

use std::sync::Arc;

use super::gpu_shared::{FirstHit, PtDisplayPush};
use super::params::{preview_fields, BrushPreview};
use super::pathtrace::PtImage;
use super::pathtrace_gpu::PtTarget;
use crate::color::linear_to_srgb;
use crate::gpu::{
    shaders, BindingKind, Bound, Buffer, Commands, ComputePipeline, ComputePipelineDesc,
    GpuContext, GpuError, Image, Profiler,
};

/// Workgroup size of `accum_display.comp`.
const WORKGROUP: [u32; 2] = [8, 8];

/// The display pass's pipeline.
pub struct PtView {
    pipeline: ComputePipeline,
}

impl PtView {
    /// Builds the pipeline.
    pub fn new(ctx: &Arc<GpuContext>) -> Result<PtView, GpuError> {
        let pipeline = ctx.create_compute_pipeline(&ComputePipelineDesc {
            name: "pt display",
            spirv: shaders::RENDER_ACCUM_DISPLAY,
            spec_constants: &[],
            push_constant_size: std::mem::size_of::<PtDisplayPush>() as u32,
            bindings: &[BindingKind::StorageImage],
        })?;
        Ok(PtView { pipeline })
    }

    /// Records the display of `target` after `spp` samples (profiled as "pt display") into the
    /// top-left corner of `image`, with `preview` tinting, and copies the first hits into
    /// `first_hits` when given (one [`FirstHit`] per pixel of the target). Record it after the
    /// samples (`GpuPathTracer::record_sample` ends with a barrier).
    #[allow(clippy::too_many_arguments)]
    pub fn record<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        target: &PtTarget,
        spp: u32,
        image: &'a Image,
        first_hits: Option<&Buffer>,
        preview: Option<&BrushPreview>,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        let (w, h) = (target.width, target.height);
        if w > image.width() || h > image.height() {
            return Err(GpuError::InvalidArgument(format!(
                "path-traced size {w}x{h} exceeds image '{}' ({}x{})",
                image.name(),
                image.width(),
                image.height()
            )));
        }
        if let Some(b) = first_hits {
            let need = w as u64 * h as u64 * std::mem::size_of::<FirstHit>() as u64;
            if b.size() < need {
                return Err(GpuError::OutOfRange {
                    name: b.name().to_string(),
                    offset: 0,
                    len: need,
                    size: b.size(),
                });
            }
        }
        let (region, color, shape) = preview_fields(preview);
        let push = PtDisplayPush {
            accum: target.accum.address(),
            first_hits: target.first_hits.address(),
            first_hits_out: first_hits.map_or(0, Buffer::address),
            width: w,
            height: h,
            preview: region,
            preview_color: color,
            preview_shape: shape,
            spp,
            _pad: [0; 2],
        };
        let groups = [w.div_ceil(WORKGROUP[0]), h.div_ceil(WORKGROUP[1]), 1];
        cmd.begin_pass(&mut profiler, "pt display");
        let r = cmd.dispatch(
            &self.pipeline,
            groups,
            bytemuck::bytes_of(&push),
            &[Bound::Image(image)],
        );
        cmd.end_pass(&mut profiler);
        r
    }
}

/// The CPU twin of the display pass: [`PtImage::to_rgba8`] with the pixels whose first hit lies
/// in `preview` tinted (in linear, before the sRGB curve).
pub fn display_cpu(image: &PtImage, preview: Option<&BrushPreview>) -> Vec<u8> {
    let quantize = super::cpu::quantize;
    let linear = image.linear();
    linear
        .chunks_exact(3)
        .zip(&image.first_hits)
        .flat_map(|(c, f)| {
            let mut c = [c[0], c[1], c[2]];
            if let Some(p) = preview.filter(|p| f.hit == 1 && p.contains(f.voxel)) {
                c = p.tint(c);
            }
            [
                quantize(linear_to_srgb(c[0])),
                quantize(linear_to_srgb(c[1])),
                quantize(linear_to_srgb(c[2])),
                255,
            ]
        })
        .collect()
}
