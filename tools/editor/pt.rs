//! The editor's path-tracing mode: the GPU path tracer (megakernel) accumulates samples over
//! frames into one [`PtTarget`] at the frame's internal resolution and `PtView` shows the mean
//! with the brush preview; any change of what the accumulation shows (camera, scene root or
//! binding, internal size, bounces, lighting) restarts it.

use std::ops::Range;
use std::sync::Arc;

use anyhow::Result;
use clap::ValueEnum;
use serde::Serialize;
use voxdag::edit::item::Root;
use voxdag::gpu::{Buffer, Commands, GpuContext, Image, Profiler};
use voxdag::render::gpu::GpuScene;
use voxdag::render::params::BrushPreview;
use voxdag::render::pathtrace::{PtSettings, Sun};
use voxdag::render::pathtrace_gpu::{GpuPathTracer, PtMode, PtTarget};
use voxdag::render::pt_view::PtView;
use voxdag::render::{Camera, RenderSettings};

/// Largest `--bounces` of the editor (the Settings slider goes to 16).
pub const MAX_EDITOR_BOUNCES: u32 = 64;
/// Largest `--spp` (samples added per frame).
pub const MAX_FRAME_SPP: u32 = 64;

/// How the editor draws the scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RenderMode {
    /// Primary rays, Lambert shading and one shadow ray (the viewer's renderer).
    Raster,
    /// Progressive path tracing (`voxdag render --pt`: constant environment, optional sun).
    Pt,
}

/// The light of the path-traced scene: a constant environment and an optional sun, as
/// `voxdag render --pt --env R,G,B --sun X,Y,Z,I` (Settings panel, `--env`, `--sun`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PtLighting {
    /// Environment radiance (linear RGB, >= 0).
    pub env: [f32; 3],
    /// Direction towards the sun (any length but zero).
    pub sun_dir: [f32; 3],
    /// The sun's irradiance on a surface facing it; 0: no sun (its shadow rays not traced).
    pub sun_intensity: f32,
}

impl PtLighting {
    /// The lighting of `--env` and `--sun` ("x,y,z,intensity"; none: intensity 0, the sun
    /// straight above), checked like `render --pt` checks them (one-line errors).
    pub fn new(env: [f32; 3], sun: Option<[f32; 4]>) -> Result<PtLighting> {
        let [x, y, z, intensity] = sun.unwrap_or([0.0, 1.0, 0.0, 0.0]);
        let lighting = PtLighting {
            env,
            sun_dir: [x, y, z],
            sun_intensity: intensity,
        };
        let mut settings = PtSettings::new(RenderSettings::new(1, 1, Camera::orbit_default(4)));
        lighting.apply(&mut settings);
        settings.validate()?;
        Ok(lighting)
    }

    /// Sets the environment and sun of `settings`.
    fn apply(&self, settings: &mut PtSettings) {
        settings.env = self.env;
        settings.sun = (self.sun_intensity > 0.0).then_some(Sun {
            dir: self.sun_dir,
            intensity: self.sun_intensity,
        });
    }
}

/// What one accumulation shows: a change of any field restarts it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PtKey {
    /// The frame's camera.
    pub camera: Camera,
    /// The internal resolution.
    pub internal: [u32; 2],
    /// The scene binding (`Document::binding`: open, import, palette, table variant).
    pub binding: u64,
    /// The hash DAG root (edits, undo, redo).
    pub root: Root,
    /// Diffuse bounces.
    pub bounces: u32,
    /// Environment and sun.
    pub lighting: PtLighting,
}

/// The path tracer and the accumulation in progress.
pub struct PtState {
    tracer: GpuPathTracer,
    view: PtView,
    target: Option<(PtKey, PtTarget)>,
    /// Samples per pixel accumulated so far.
    pub samples: u32,
}

impl PtState {
    /// Builds the pipelines (the hash DAG variant of the megakernel on the first frame).
    pub fn new(ctx: &Arc<GpuContext>) -> Result<PtState> {
        Ok(PtState {
            tracer: GpuPathTracer::new(ctx)?,
            view: PtView::new(ctx)?,
            target: None,
            samples: 0,
        })
    }

    /// Restarts the accumulation unless it already shows `key` (waiting for frames in flight,
    /// which read the old one), and returns the sample indices this frame records: up to `spp`
    /// more, at most `max` in all.
    pub fn prepare(
        &mut self,
        ctx: &Arc<GpuContext>,
        scene: &GpuScene,
        key: PtKey,
        spp: u32,
        max: u32,
    ) -> Result<Range<u32>> {
        if self.target.as_ref().is_none_or(|(k, _)| *k != key) {
            let mut settings = PtSettings::new(RenderSettings::new(
                key.internal[0],
                key.internal[1],
                key.camera,
            ));
            settings.bounces = key.bounces;
            key.lighting.apply(&mut settings);
            ctx.wait_idle()?;
            self.target = None;
            let target = self
                .tracer
                .create_target(scene, &settings, PtMode::Megakernel)?;
            self.target = Some((key, target));
            self.samples = 0;
        }
        // A limit lowered below the samples already in stops adding (the mean stays right).
        let start = self.samples;
        self.samples = (start + spp).min(max.max(1)).max(start);
        Ok(start..self.samples)
    }

    /// Records `samples` of the prepared accumulation, then its display into `image` with
    /// `preview`, the first hits copied to `first_hits`.
    #[allow(clippy::too_many_arguments)]
    pub fn record<'a>(
        &'a self,
        cmd: &mut Commands<'a>,
        scene: &GpuScene,
        samples: Range<u32>,
        image: &'a Image,
        first_hits: &Buffer,
        preview: Option<&BrushPreview>,
        mut profiler: Option<&mut Profiler>,
    ) -> Result<()> {
        let (_, target) = self
            .target
            .as_ref()
            .ok_or_else(|| anyhow::anyhow!("path tracing: no accumulation prepared"))?;
        for s in samples {
            self.tracer
                .record_sample(cmd, scene, target, s, profiler.as_deref_mut())?;
        }
        self.view.record(
            cmd,
            target,
            self.samples,
            image,
            Some(first_hits),
            preview,
            profiler,
        )?;
        Ok(())
    }
}
