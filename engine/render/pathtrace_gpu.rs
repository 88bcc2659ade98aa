//! GPU path tracers: a megakernel (`pt_mega.comp`, one invocation runs whole paths, of
//! `PT_MEGA_PATHS` pixels in turn) and a wavefront tracer (Laine, Karras & Aila 2013:
//! `pt_generate`, then per bounce `pt_extend` -> `pt_shade` -> `pt_shadow`, then
//! `pt_accumulate`), both over an uploaded
//! [`GpuScene`] and both the twins of the CPU reference ([`super::pathtrace::render_pt_cpu`]):
//! same RNG keys per (pixel, sample, bounce, seed), same arithmetic.
//!
//! Wavefront queues: paths live per pixel; the extension queue (pixel indices) is rebuilt after
//! every shade pass by a stable stream compaction of the shade pass's survival flags
//! (`compute::Primitives::record_compact`), the shadow queue by atomic append; each queue's
//! count is turned into indirect arguments on the GPU, so every pass after `pt_generate` is
//! sized there (`Commands::dispatch_indirect`). All passes of one sample are recorded into one
//! submission. Progressive accumulation: a [`PtTarget`] sums samples into a `vec4` per pixel;
//! recording sample 0 clears it (restart after a camera or scene change).

use std::sync::{Arc, OnceLock};

use super::format::TraversalFormat;
use super::gpu::GpuScene;
use super::gpu_shared::{FirstHit, PtPush};
use super::params::{RenderParams, FLAG_HAS_COLORS};
use super::pathtrace::{srgb_lut, PathTraceError, PtImage, PtSettings};
use crate::compute::{Primitives, ScanScratch, COUNT_ARGS_BYTES};
use crate::dag::Svdag;
use crate::gpu::{
    made_once, shaders, BindingKind, Bound, Buffer, Commands, ComputePipeline, ComputePipelineDesc,
    GpuContext, GpuError, MemLocation, Profiler,
};

/// Workgroup size of `pt_mega.comp` (specialization constants 0 and 1).
const WORKGROUP: [u32; 2] = [8, 8];
/// Pixels each megakernel invocation traces in turn (`pt_mega.comp`'s specialization constant
/// 3): a workgroup covers 8 x (8 * PT_MEGA_PATHS) pixels.
const PT_MEGA_PATHS: u32 = 4;
/// Invocations per workgroup of the wavefront passes (`PT_WAVE_GROUP` in `pt_wave.glsl`).
pub const PT_WAVE_GROUP: u32 = 64;

/// Which GPU path tracer runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PtMode {
    /// One invocation traces whole paths, of `PT_MEGA_PATHS` pixels in turn.
    Megakernel,
    /// Generate / extend / shade / shadow / accumulate passes connected by queues.
    Wavefront,
}

/// The wavefront tracer's state and queues.
struct WaveBuffers {
    paths: Buffer,
    queues: [Buffer; 2],
    flags: Buffer,
    ext_count: Buffer,
    shadow_queue: Buffer,
    shadow_count: Buffer,
    scratch: ScanScratch,
}

/// The accumulation of one progressive render: constants, accumulation and first-hit buffers,
/// and the wavefront queues when the mode needs them.
pub struct PtTarget {
    mode: PtMode,
    pub(super) width: u32,
    pub(super) height: u32,
    bounces: u32,
    /// Whether every sample needs colour indices (the albedo reads voxel colours); else only
    /// the first hits of sample 0 do.
    needs_color_index: bool,
    /// Whether a sun lights the scene (the megakernel then traces shadow rays).
    sun: bool,
    render_params: Buffer,
    pt_params: Buffer,
    _lut: Buffer,
    /// Read by `pt_view` too (the editor's display pass).
    pub(super) accum: Buffer,
    pub(super) first_hits: Buffer,
    wave: Option<WaveBuffers>,
}

impl PtTarget {
    /// The tracer this target was made for.
    pub fn mode(&self) -> PtMode {
        self.mode
    }

    /// Reads back the accumulation (`spp` = samples recorded so far) and the first hits.
    pub fn read(&self, ctx: &Arc<GpuContext>, spp: u32) -> Result<PtImage, GpuError> {
        Ok(PtImage {
            width: self.width,
            height: self.height,
            spp,
            accum: ctx.download::<[f32; 4]>(&self.accum)?,
            first_hits: ctx.download::<FirstHit>(&self.first_hits)?,
            rays: None,
        })
    }
}

/// The megakernel and wavefront pipelines of one DAG format (every pt shader includes
/// traverse.glsl, so each has one variant per format).
struct PtPipelines {
    generate: ComputePipeline,
    shadow: ComputePipeline,
    accumulate: ComputePipeline,
    /// The megakernel per [`TracingVariant::index`], the extend and shade passes per
    /// colour-index variant (specialization constants 2 and 4), made on first use.
    mega: [OnceLock<ComputePipeline>; 4],
    extend: [OnceLock<ComputePipeline>; 2],
    shade: [OnceLock<ComputePipeline>; 2],
}

/// The passes made per [`TracingVariant`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum VariantPass {
    /// `pt_mega.comp`: per colour index and sun.
    Megakernel,
    /// `pt_extend.comp`: per colour index.
    Extend,
    /// `pt_shade.comp`: per colour index (the colour decode of each hit).
    Shade,
}

/// Which code a pipeline compiles in. lavapipe runs both sides of an `if` (masked) and every
/// loop body at least once, so code that no invocation needs still costs: the colour index
/// after each traversal and the colour decode of each hit, and in the megakernel the sun's
/// shadow-ray traversal after each hit (docs/pathtracing.md, "Code that no path needs").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct TracingVariant {
    /// Colour indices computed and voxel colours decoded (specialization constant 2).
    colors: bool,
    /// Shadow rays towards the sun traced (megakernel only: specialization constant 4).
    sun: bool,
}

impl TracingVariant {
    /// Slot of the megakernel variant in `PtPipelines::mega`.
    fn index(self) -> usize {
        self.colors as usize | (self.sun as usize) << 1
    }
}

/// The GPU path tracers' pipelines, created per DAG format on first use.
pub struct GpuPathTracer {
    ctx: Arc<GpuContext>,
    pipelines: Vec<OnceLock<PtPipelines>>,
    primitives: Primitives,
}

/// Workgroups for `n` invocations of a wavefront pass as the 2D grid of `record_indirect_args`.
fn wave_grid(n: u32) -> [u32; 3] {
    let groups = n.div_ceil(PT_WAVE_GROUP);
    let x = groups.min(crate::compute::GRID_X);
    [x, groups.div_ceil(crate::compute::GRID_X).max(1), 1]
}

impl GpuPathTracer {
    /// Builds the svdag32 megakernel and wavefront pipelines (the other formats' on first use).
    pub fn new(ctx: &Arc<GpuContext>) -> Result<GpuPathTracer, GpuError> {
        let tracer = GpuPathTracer {
            ctx: Arc::clone(ctx),
            pipelines: (0..shaders::RENDER_PT_MEGA_BY_FORMAT.len())
                .map(|_| OnceLock::new())
                .collect(),
            primitives: Primitives::new(ctx)?,
        };
        tracer.pipelines(TraversalFormat::Svdag32)?;
        Ok(tracer)
    }

    /// The pipelines of `format`, created unless they exist.
    fn pipelines(&self, format: TraversalFormat) -> Result<&PtPipelines, GpuError> {
        let i = format.index();
        made_once(&self.pipelines[i], || {
            let make = |pass, spirv| self.make_pipeline(format, pass, spirv, &[]);
            Ok(PtPipelines {
                generate: make("generate", shaders::RENDER_PT_GENERATE_BY_FORMAT[i])?,
                shadow: make("shadow", shaders::RENDER_PT_SHADOW_BY_FORMAT[i])?,
                accumulate: make("accumulate", shaders::RENDER_PT_ACCUMULATE_BY_FORMAT[i])?,
                mega: Default::default(),
                extend: Default::default(),
                shade: Default::default(),
            })
        })
    }

    /// A pipeline of pass `pass` of `format`'s traversal variant.
    fn make_pipeline(
        &self,
        format: TraversalFormat,
        pass: &str,
        spirv: &[u32],
        spec: &[u32],
    ) -> Result<ComputePipeline, GpuError> {
        self.ctx.create_compute_pipeline(&ComputePipelineDesc {
            name: &format!("pt {pass} ({})", format.name()),
            spirv,
            spec_constants: spec,
            push_constant_size: std::mem::size_of::<PtPush>() as u32,
            bindings: &[BindingKind::TexelBuffer],
        })
    }

    /// `pass` of `format` compiled for `variant` (only the megakernel reads `variant.sun`:
    /// the wavefront's shadow rays are the shadow pass's), made on first use.
    fn variant_pipeline<'a>(
        &'a self,
        pipes: &'a PtPipelines,
        format: TraversalFormat,
        pass: VariantPass,
        variant: TracingVariant,
    ) -> Result<&'a ComputePipeline, GpuError> {
        let i = format.index();
        let (slot, spirv, name) = match pass {
            VariantPass::Megakernel => (
                &pipes.mega[variant.index()],
                shaders::RENDER_PT_MEGA_BY_FORMAT[i],
                "megakernel",
            ),
            VariantPass::Extend => (
                &pipes.extend[variant.colors as usize],
                shaders::RENDER_PT_EXTEND_BY_FORMAT[i],
                "extend",
            ),
            VariantPass::Shade => (
                &pipes.shade[variant.colors as usize],
                shaders::RENDER_PT_SHADE_BY_FORMAT[i],
                "shade",
            ),
        };
        made_once(slot, || {
            // Constants 0, 1, 3 and 4 are the megakernel's workgroup, paths per invocation and
            // sun (the wavefront passes have none of them: ignored).
            let spec = [
                WORKGROUP[0],
                WORKGROUP[1],
                variant.colors as u32,
                PT_MEGA_PATHS,
                variant.sun as u32,
            ];
            let mega = pass == VariantPass::Megakernel;
            let name = format!(
                "{name}{}{}",
                if variant.colors {
                    ""
                } else {
                    ", no colour index"
                },
                if variant.sun || !mega { "" } else { ", no sun" },
            );
            self.make_pipeline(format, &name, spirv, &spec)
        })
    }

    /// Allocates the accumulation of a `settings`-sized render of `scene` for `mode` and writes
    /// its constants (validated first: one-line errors for bad settings).
    pub fn create_target(
        &self,
        scene: &GpuScene,
        settings: &PtSettings,
        mode: PtMode,
    ) -> Result<PtTarget, PathTraceError> {
        let ctx = &self.ctx;
        let mut pt = settings.params()?;
        // RenderParams::with_colors reads only the resolution of the DAG.
        let header = Svdag {
            resolution: scene.resolution(),
            words: Vec::new(),
            level_starts: Vec::new(),
            colors: Vec::new(),
        };
        let params = RenderParams::with_colors(&settings.render, &header, scene.color_count())?;
        // `pt_needs_color_index` in pt_common.glsl.
        let needs_color_index = pt.env[3] < 0.0 && params.flags & FLAG_HAS_COLORS != 0;
        let pixels = pt.pixels as u64;
        let lut = ctx.upload("pt srgb lut", &srgb_lut())?;
        let accum = ctx.create_buffer("pt accumulation", pixels * 16, MemLocation::GpuOnly)?;
        let first_hits = ctx.create_buffer(
            "pt first hits",
            pixels * std::mem::size_of::<FirstHit>() as u64,
            MemLocation::GpuOnly,
        )?;
        pt.accum = accum.address();
        pt.first_hits = first_hits.address();
        pt.srgb_lut = lut.address();
        let wave = if mode == PtMode::Wavefront {
            let queue = |name| ctx.create_buffer(name, pixels * 4, MemLocation::GpuOnly);
            let w = WaveBuffers {
                // `PtPath` (pt_wave.glsl): four vec4s, a uint64_t, a float and a uint.
                paths: ctx.create_buffer("pt paths", pixels * 80, MemLocation::GpuOnly)?,
                queues: [queue("pt queue a")?, queue("pt queue b")?],
                flags: queue("pt survival flags")?,
                ext_count: ctx.create_buffer(
                    "pt extension count",
                    COUNT_ARGS_BYTES,
                    MemLocation::GpuOnly,
                )?,
                // `PtShadowRay`: two vec4s; at most one per path and bounce.
                shadow_queue: ctx.create_buffer(
                    "pt shadow queue",
                    pixels * 32,
                    MemLocation::GpuOnly,
                )?,
                shadow_count: ctx.create_buffer(
                    "pt shadow count",
                    COUNT_ARGS_BYTES,
                    MemLocation::GpuOnly,
                )?,
                scratch: self.primitives.scan_scratch(pixels)?,
            };
            pt.paths = w.paths.address();
            pt.queue_a = w.queues[0].address();
            pt.queue_b = w.queues[1].address();
            pt.flags = w.flags.address();
            pt.ext_count = w.ext_count.address();
            pt.shadow_queue = w.shadow_queue.address();
            pt.shadow_count = w.shadow_count.address();
            Some(w)
        } else {
            None
        };
        let mut render_params = ctx.create_buffer(
            "pt render params",
            std::mem::size_of::<RenderParams>() as u64,
            MemLocation::CpuToGpu,
        )?;
        ctx.write_mapped(&mut render_params, 0, std::slice::from_ref(&params))?;
        let mut pt_params = ctx.create_buffer(
            "pt params",
            std::mem::size_of_val(&pt) as u64,
            MemLocation::CpuToGpu,
        )?;
        ctx.write_mapped(&mut pt_params, 0, std::slice::from_ref(&pt))?;
        Ok(PtTarget {
            mode,
            width: settings.render.width,
            height: settings.render.height,
            bounces: settings.bounces,
            needs_color_index,
            sun: pt.sun[3] > 0.0,
            render_params,
            pt_params,
            _lut: lut,
            accum,
            first_hits,
            wave,
        })
    }

    /// Records sample `sample` of `target` into `cmd` (sample 0 clears the accumulation and
    /// writes the first hits). Passes are profiled as "pt megakernel", or "pt generate",
    /// "pt extend", "pt shade", "pt shadow" (+ the compaction's and indirect arguments' passes)
    /// and "pt accumulate". Keep `scene` and `target` alive until `cmd` has completed.
    pub fn record_sample<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        scene: &GpuScene,
        target: &'a PtTarget,
        sample: u32,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<(), GpuError> {
        let format = scene.format();
        let pipes = self.pipelines(format)?;
        // Sample 0 fills the first-hit buffer (colour indices included) on its first bounce;
        // the rest need colour indices only when the albedo reads voxel colours.
        let variant = |bounce: u32| TracingVariant {
            colors: target.needs_color_index || (sample == 0 && bounce == 0),
            sun: target.sun,
        };
        if sample == 0 {
            cmd.fill_buffer(&target.accum, 0);
        }
        let mut push = PtPush {
            params: target.render_params.address(),
            pt: target.pt_params.address(),
            words: scene.words.address(),
            node_voxels: scene.node_voxels.address(),
            color_words: scene.color_words.address(),
            chunk_starts: scene.chunk_starts.address(),
            chunk_offsets: scene.chunk_offsets.address(),
            color_format: scene.color_format as u32,
            chunk_count: scene.chunk_count,
            sample_index: sample,
            bounce: 0,
            dag_root: scene.dag_root,
            _pad: 0,
        };
        let tables = [Bound::Texels(&scene.tables)];
        let pixels = target.width * target.height;
        let Some(w) = &target.wave else {
            let groups = [
                target.width.div_ceil(WORKGROUP[0]),
                target.height.div_ceil(PT_MEGA_PATHS * WORKGROUP[1]),
                1,
            ];
            cmd.begin_pass(&mut profiler, "pt megakernel");
            let mega = self.variant_pipeline(pipes, format, VariantPass::Megakernel, variant(0))?;
            let r = cmd.dispatch(mega, groups, bytemuck::bytes_of(&push), &tables);
            cmd.end_pass(&mut profiler);
            cmd.barrier();
            return r;
        };
        cmd.begin_pass(&mut profiler, "pt generate");
        let r = cmd.dispatch(
            &pipes.generate,
            wave_grid(pixels),
            bytemuck::bytes_of(&push),
            &tables,
        );
        cmd.end_pass(&mut profiler);
        r?;
        self.primitives.record_indirect_args(
            cmd,
            &w.ext_count,
            PT_WAVE_GROUP,
            profiler.as_deref_mut(),
        )?;
        for k in 0..=target.bounces {
            push.bounce = k;
            let push_bytes = bytemuck::bytes_of(&push);
            cmd.fill_buffer(&w.flags, 0);
            cmd.fill_buffer(&w.shadow_count, 0);
            cmd.begin_pass(&mut profiler, "pt extend");
            let extend = self.variant_pipeline(pipes, format, VariantPass::Extend, variant(k))?;
            let r = cmd.dispatch_indirect(extend, &w.ext_count, 4, push_bytes, &tables);
            cmd.end_pass(&mut profiler);
            r?;
            cmd.barrier();
            cmd.begin_pass(&mut profiler, "pt shade");
            let shade = self.variant_pipeline(pipes, format, VariantPass::Shade, variant(k))?;
            let r = cmd.dispatch_indirect(shade, &w.ext_count, 4, push_bytes, &tables);
            cmd.end_pass(&mut profiler);
            r?;
            self.primitives.record_indirect_args(
                cmd,
                &w.shadow_count,
                PT_WAVE_GROUP,
                profiler.as_deref_mut(),
            )?;
            cmd.begin_pass(&mut profiler, "pt shadow");
            let r = cmd.dispatch_indirect(&pipes.shadow, &w.shadow_count, 4, push_bytes, &tables);
            cmd.end_pass(&mut profiler);
            r?;
            cmd.barrier();
            if k < target.bounces {
                let (cur, next) = (&w.queues[(k & 1) as usize], &w.queues[(!k & 1) as usize]);
                self.primitives.record_compact(
                    cmd,
                    cur,
                    &w.flags,
                    pixels as u64,
                    next,
                    &w.ext_count,
                    PT_WAVE_GROUP,
                    &w.scratch,
                    profiler.as_deref_mut(),
                )?;
            }
        }
        cmd.begin_pass(&mut profiler, "pt accumulate");
        let r = cmd.dispatch(
            &pipes.accumulate,
            wave_grid(pixels),
            bytemuck::bytes_of(&push),
            &tables,
        );
        cmd.end_pass(&mut profiler);
        cmd.barrier();
        r
    }

    /// Renders `settings.spp` samples with `mode`, blocking, and reads the result back. With a
    /// profiler, each sample is submitted and resolved on its own (timestamps per pass);
    /// without, samples are submitted back to back (one submission each).
    pub fn render(
        &self,
        scene: &GpuScene,
        settings: &PtSettings,
        mode: PtMode,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<PtImage, PathTraceError> {
        let target = self.create_target(scene, settings, mode)?;
        let mut last = None;
        for s in 0..settings.spp {
            let mut cmd = self.ctx.begin_commands("path trace sample")?;
            self.record_sample(&mut cmd, scene, &target, s, profiler.as_deref_mut())?;
            match profiler.as_deref_mut() {
                Some(p) => {
                    cmd.submit()?;
                    p.resolve()?;
                }
                None => last = Some(cmd.submit_async()?),
            }
        }
        if let Some(s) = last {
            s.wait()?;
        }
        Ok(target.read(&self.ctx, settings.spp)?)
    }
}
