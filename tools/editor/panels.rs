//! The editor's Settings and Profiler panels: render mode (raster or path tracing, its
//! bounces, samples and light), the table variant switched at run time (the hash DAG rebuilt from the
//! current scene), render scale, vsync; per-pass GPU times of the last
//! frame, a rolling graph of frame times, the last edit's kernels, and Chrome traces of the next
//! N frames (`Profiler::write_chrome_trace`, as `--trace` of `voxdag render` / `edit`).

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::{anyhow, Result};
use clap::ValueEnum;
use egui::SliderClamping;
use voxdag::gpu::{GpuContext, Profiler};
use voxdag::hash::HashVariant;
use voxdag::render::gpu::GpuRenderer;

use super::pt::PtLighting;
use super::{editor_tables, pack_colour, Document, RenderMode, Running};
use crate::edit::TableArg;
use crate::view::MOTION_TARGET_MS;
use crate::window::{MAX_FLY_SPEED, MIN_FLY_SPEED, MIN_SCALE};

/// Frame times kept for the Profiler's graph.
pub const GRAPH_FRAMES: usize = 240;
/// Largest environment radiance and sun intensity the Settings panel offers (the flags take
/// any finite value >= 0).
const MAX_RADIANCE: f32 = 16.0;
/// Most frames one trace records (the profiler's timestamp pool holds about 170 frames).
pub const MAX_TRACE_FRAMES: u32 = 100;

/// A Chrome trace being recorded: every frame's GPU passes, edit kernels and CPU spans go
/// to one profiler until `frames_left` reaches 0, then it is written to `path`.
pub struct TraceRecording {
    /// Frames still to record.
    pub frames_left: u32,
    /// Where the trace goes.
    pub path: PathBuf,
    /// The profiler of the recorded frames.
    pub profiler: Profiler,
}

/// The Settings and Profiler panels' state.
pub struct PanelState {
    /// Frame times (ms), oldest first.
    pub frame_times: VecDeque<f32>,
    /// Frames the next trace records (Profiler panel).
    pub trace_frames: u32,
    /// Where the next trace goes (Profiler panel).
    pub trace_path: String,
    /// The trace being recorded.
    pub trace: Option<TraceRecording>,
    /// Vsync on (FIFO).
    pub vsync: bool,
    /// Vsync toggled in this frame's panels.
    pub vsync_changed: bool,
    /// A table variant picked in this frame's panels, switched to after them.
    pub pending_variant: Option<HashVariant>,
}

impl PanelState {
    /// Vsync as started, a 10-frame trace to `trace.json`.
    pub fn new(vsync: bool) -> PanelState {
        PanelState {
            frame_times: VecDeque::with_capacity(GRAPH_FRAMES),
            trace_frames: 10,
            trace_path: "trace.json".into(),
            trace: None,
            vsync,
            vsync_changed: false,
            pending_variant: None,
        }
    }

    /// Adds one frame time to the graph.
    pub fn push_frame_time(&mut self, ms: f32) {
        if self.frame_times.len() == GRAPH_FRAMES {
            self.frame_times.pop_front();
        }
        self.frame_times.push_back(ms);
    }
}

/// The table variant after `v` in the order of `--table` (T cycles through them).
pub fn next_variant(v: HashVariant) -> HashVariant {
    let all: Vec<HashVariant> = TableArg::value_variants()
        .iter()
        .map(|t| t.variant())
        .collect();
    let i = all.iter().position(|&x| x == v).unwrap_or(0);
    all[(i + 1) % all.len()]
}

impl Document {
    /// Rebuilds the hash DAG with tables of `variant` from the current scene (voxels and
    /// materials) and binds it. The undo history is dropped: its roots live in the old tables.
    pub(super) fn switch_variant(
        &mut self,
        ctx: &Arc<GpuContext>,
        renderer: &GpuRenderer,
        variant: HashVariant,
    ) -> Result<()> {
        let palette: Vec<u32> = self.palette.iter().map(|&c| pack_colour(c)).collect();
        let mut file = self
            .dag
            .download()?
            .to_file(self.dag.root(), Some(&palette))?;
        let materials = file
            .materials
            .take()
            .ok_or_else(|| anyhow!("the editor's hash DAG has no materials"))?;
        let svdag = file.into_svdag(&self.path)?;
        let dag = editor_tables(ctx, &svdag, &materials, self.dag.undo_depth(), variant)?;
        let scene = renderer.bind_hash_dag(&dag, Some(&self.palette))?;
        // Frames in flight read the old tables and binding.
        ctx.wait_idle()?;
        self.scene = scene;
        self.binding = super::next_binding();
        self.dag = dag;
        self.undo = 0;
        self.redo = 0;
        // Node pointers name items of the old tables.
        self.counts.clear();
        self.node_voxels.clear();
        Ok(())
    }
}

impl Running {
    /// Settings: render mode and path-tracing settings, table variant, render scale, dynamic
    /// scale, vsync.
    pub(super) fn settings_panel(&mut self, ui: &mut egui::Ui, extent: [u32; 2]) {
        ui.horizontal(|ui| {
            ui.label("render mode (P)");
            ui.radio_value(&mut self.render_mode, RenderMode::Raster, "raster");
            ui.radio_value(&mut self.render_mode, RenderMode::Pt, "path tracing");
        });
        // The flags allow more than the sliders offer: existing values stay (`Edits`).
        ui.add(
            egui::Slider::new(&mut self.bounces, 0..=16)
                .clamping(SliderClamping::Edits)
                .text("bounces"),
        );
        ui.add(
            egui::Slider::new(&mut self.spp, 1..=16)
                .clamping(SliderClamping::Edits)
                .text("samples per frame"),
        );
        ui.add(
            egui::DragValue::new(&mut self.max_samples)
                .range(1..=1 << 16)
                .prefix("stop at ")
                .suffix(" samples"),
        );
        lighting_controls(ui, &mut self.lighting);
        if self.render_mode == RenderMode::Pt {
            ui.label(format!("{} samples accumulated", self.pt_samples()));
        }
        ui.separator();
        let current = self.doc.dag.config().variant;
        egui::ComboBox::from_label("hash table variant (T)")
            .selected_text(current.name())
            .show_ui(ui, |ui| {
                for t in TableArg::value_variants() {
                    let v = t.variant();
                    if ui.selectable_label(v == current, v.name()).clicked() && v != current {
                        self.ui.pending_variant = Some(v);
                    }
                }
            });
        ui.label("(a switch rebuilds the tables from the scene and drops the undo history)");
        ui.add(
            egui::Slider::new(&mut self.input.fly_speed, MIN_FLY_SPEED..=MAX_FLY_SPEED)
                .logarithmic(true)
                .text("fly speed (Shift + wheel)"),
        );
        ui.add(egui::Slider::new(&mut self.user_scale, MIN_SCALE..=1.0).text("render scale"));
        ui.checkbox(
            &mut self.dynamic_scale,
            "lower scale while moving / editing",
        );
        ui.label(format!(
            "internal {}x{} of {}x{} (scale {:.2})",
            self.internal[0], self.internal[1], extent[0], extent[1], self.scale
        ));
        if ui
            .checkbox(&mut self.ui.vsync, "vsync (off: MAILBOX / IMMEDIATE)")
            .changed()
        {
            self.ui.vsync_changed = true;
        }
        ui.label(format!(
            "present mode {}, {} frames in flight",
            self.win.presenter.stats().present_mode,
            self.win.presenter.frames_in_flight()
        ));
    }

    /// Applies what this frame's Settings panel changed: vsync (the swapchain is rebuilt
    /// before the next frame) and the table variant (errors are shown, the scene stays).
    pub(super) fn apply_settings(&mut self) -> Result<()> {
        if std::mem::take(&mut self.ui.vsync_changed) {
            self.win.presenter.set_vsync(self.ui.vsync)?;
        }
        if let Some(variant) = self.ui.pending_variant.take() {
            self.message = Some(
                match self.doc.switch_variant(&self.ctx, &self.renderer, variant) {
                    Ok(()) => format!("hash tables rebuilt as {}", variant.name()),
                    Err(e) => format!("switching to {} failed: {e:#}", variant.name()),
                },
            );
        }
        Ok(())
    }

    /// Profiler: fps, per-pass GPU times of the last frame, the frame-time graph, the last
    /// edit's kernels, trace recording.
    pub(super) fn profiler_panel(&mut self, ui: &mut egui::Ui) {
        let fps = if self.frame_ms > 0.0 {
            1e3 / self.frame_ms
        } else {
            0.0
        };
        ui.label(format!("{fps:.1} fps, {:.2} ms/frame", self.frame_ms));
        self.frame_graph(ui);
        ui.label("GPU passes (last frame)");
        for p in &self.last_passes {
            ui.label(format!("  {}: {:.2} ms", p.name, p.gpu_ms));
        }
        ui.separator();
        match &self.last_edit {
            Some(e) => {
                ui.label(format!(
                    "last edit: {} r {:.1} at {:.0?}, {:.2} ms, latency {}",
                    e.tool,
                    e.radius,
                    e.center,
                    e.ms,
                    e.latency_ms
                        .map_or("-".to_string(), |l| format!("{l:.1} ms"))
                ));
            }
            None => {
                ui.label("no edit yet");
            }
        }
        // At most one edit a second is profiled (profiling costs lavapipe about an edit).
        if let Some((_, e)) = &self.profiled_edit {
            ui.label(format!(
                "last profiled edit: {} r {:.1}, {:.2} ms",
                e.tool, e.radius, e.ms
            ));
            for (name, ms) in &e.kernels {
                ui.label(format!("  {name}: {ms:.3} ms"));
            }
        }
        ui.separator();
        match &self.ui.trace {
            Some(t) => {
                ui.label(format!(
                    "recording {}: {} frames left",
                    t.path.display(),
                    t.frames_left
                ));
            }
            None => {
                ui.horizontal(|ui| {
                    ui.add(
                        egui::DragValue::new(&mut self.ui.trace_frames)
                            .range(1..=MAX_TRACE_FRAMES)
                            .suffix(" frames"),
                    );
                    ui.text_edit_singleline(&mut self.ui.trace_path);
                });
                if ui.button("record a Chrome trace").clicked() {
                    let path = PathBuf::from(&self.ui.trace_path);
                    let frames = self.ui.trace_frames;
                    if let Err(e) = self.start_trace(path, frames) {
                        self.message = Some(format!("trace: {e:#}"));
                    }
                }
            }
        }
    }

    /// Starts recording the next `frames` frames into a Chrome trace at `path`.
    pub(super) fn start_trace(&mut self, path: PathBuf, frames: u32) -> Result<()> {
        crate::commands::check_output(&path)?;
        self.ui.trace = Some(TraceRecording {
            frames_left: frames.clamp(1, MAX_TRACE_FRAMES),
            path,
            profiler: Profiler::new(&self.ctx)?,
        });
        Ok(())
    }

    /// Counts one recorded frame of the trace; after the last, resolves and writes it.
    pub(super) fn trace_frame_done(&mut self) -> Result<()> {
        let Some(t) = &mut self.ui.trace else {
            return Ok(());
        };
        t.frames_left -= 1;
        if t.frames_left > 0 {
            return Ok(());
        }
        let mut t = self.ui.trace.take().expect("checked above");
        t.profiler.resolve()?;
        t.profiler.write_chrome_trace(&t.path)?;
        self.message = Some(format!("Chrome trace written to {}", t.path.display()));
        self.traces_written += 1;
        Ok(())
    }

    /// The rolling graph of frame times, scaled to the largest (at least the motion target).
    fn frame_graph(&self, ui: &mut egui::Ui) {
        let times = &self.ui.frame_times;
        let top = times
            .iter()
            .copied()
            .fold(MOTION_TARGET_MS as f32, f32::max);
        let (rect, _) = ui.allocate_exact_size(egui::vec2(240.0, 60.0), egui::Sense::hover());
        let painter = ui.painter_at(rect);
        painter.rect_filled(rect, 0.0, egui::Color32::from_black_alpha(140));
        let target_y = rect.bottom() - MOTION_TARGET_MS as f32 / top * rect.height();
        painter.hline(
            rect.x_range(),
            target_y,
            egui::Stroke::new(1.0, egui::Color32::DARK_GRAY),
        );
        let step = rect.width() / (GRAPH_FRAMES - 1) as f32;
        let points: Vec<egui::Pos2> = times
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                egui::pos2(
                    rect.left() + i as f32 * step,
                    rect.bottom() - t / top * rect.height(),
                )
            })
            .collect();
        painter.add(egui::Shape::line(
            points,
            egui::Stroke::new(1.0, egui::Color32::LIGHT_GREEN),
        ));
        ui.label(format!(
            "frame times, last {} (top {top:.0} ms, line {MOTION_TARGET_MS:.0} ms)",
            times.len()
        ));
    }
}

/// Path tracing's light: the environment radiance per channel, the sun's intensity (0: off)
/// and its direction as azimuth and elevation (degrees above the grid's x-z plane). The
/// direction is written back only when a slider moves, so an untouched panel never restarts
/// the accumulation.
fn lighting_controls(ui: &mut egui::Ui, lighting: &mut PtLighting) {
    ui.horizontal(|ui| {
        ui.label("environment");
        for (v, name) in lighting.env.iter_mut().zip(["r ", "g ", "b "]) {
            ui.add(
                egui::DragValue::new(v)
                    .range(0.0..=MAX_RADIANCE)
                    .clamp_existing_to_range(false)
                    .speed(0.01)
                    .prefix(name),
            );
        }
    });
    ui.add(
        egui::Slider::new(&mut lighting.sun_intensity, 0.0..=MAX_RADIANCE)
            .clamping(SliderClamping::Edits)
            .text("sun intensity (0: off)"),
    );
    let [x, y, z] = lighting.sun_dir;
    let horizontal = x.hypot(z);
    let mut azimuth = z.atan2(x).to_degrees();
    let mut elevation = y.atan2(horizontal).to_degrees();
    let turned = ui
        .add(egui::Slider::new(&mut azimuth, -180.0..=180.0).text("sun azimuth"))
        .changed()
        | ui.add(egui::Slider::new(&mut elevation, -90.0..=90.0).text("sun elevation"))
            .changed();
    if turned {
        let (a, e) = (azimuth.to_radians(), elevation.to_radians());
        lighting.sun_dir = [e.cos() * a.cos(), e.sin(), e.cos() * a.sin()];
    }
}
