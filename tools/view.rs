//! `voxdag view`: a window that renders a scene every frame with the primary-ray renderer, an
//! orbit/fly camera and an egui overlay (fps, GPU pass times, render scale). See docs/viewer.md.

use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Result};
use serde::Serialize;
use voxdag::dag::Svdag;
use voxdag::gpu::{
    GpuContext, Image, OverlayFrame, PassTiming, PhaseClock, PhaseTime, PresenterOptions,
    PresenterStats, Profiler,
};
use voxdag::render::cpu::ColorSource;
use voxdag::render::gpu::{GpuRenderer, GpuScene, RenderFrame};
use voxdag::render::{Camera, RenderOutput, RenderSettings};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::WindowId;

use crate::commands::{check_output, load_svdag_stored, write_json};
use crate::window::{require_display, CameraInput, GpuWindow, MIN_SCALE};
use crate::ViewArgs;

/// GPU time per frame the dynamic render scale aims for while the camera moves.
pub const MOTION_TARGET_MS: f64 = 40.0;
/// Frames left out of the frame-rate statistics (pipeline warm-up, first swapchain).
const WARMUP_FRAMES: usize = 5;
/// The timed phases of one frame-loop iteration, in order (`--stats-json` `cpu_phases`). The
/// three marked "wait" block on the GPU or the presentation engine and are not CPU-loop cost.
const PHASES: [&str; 12] = [
    "slot wait (wait)",
    "acquire (wait)",
    "profiler resolve",
    "input + camera",
    "egui layout",
    "egui tessellate",
    "render record",
    "overlay textures",
    "overlay record",
    "submit",
    "present (wait)",
    "other",
];
/// Indices into [`PHASES`] of the waits.
const WAIT_PHASES: [usize; 3] = [0, 1, 10];

/// The presenter's cumulative times that split `end_frame` and the waits, as
/// (slot wait, acquire, textures, record, submit, present).
fn presenter_times(stats: &PresenterStats) -> [PhaseTime; 6] {
    [
        stats.slot_wait,
        stats.acquire,
        stats.textures,
        stats.record,
        stats.submit,
        stats.present,
    ]
}

/// `voxdag view`.
pub fn view(args: &ViewArgs) -> Result<()> {
    if args.screenshot.is_some() && args.frames.is_none() {
        bail!("--screenshot needs --frames N (the frame that is saved)");
    }
    if !(MIN_SCALE..=1.0).contains(&args.render_scale) {
        bail!(
            "--render-scale {} out of range ({MIN_SCALE}..=1)",
            args.render_scale
        );
    }
    for path in [&args.screenshot, &args.stats_json].into_iter().flatten() {
        check_output(path)?;
    }
    let display = require_display("view")?;
    let (dag, stored) = load_svdag_stored(&args.file)?;
    let event_loop = EventLoop::new()
        .map_err(|e| anyhow!("cannot open a window on display {display:?}: {e}"))?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let mut app = App {
        args,
        dag,
        stored,
        running: None,
        context: None,
        error: None,
        report: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| anyhow!("window event loop: {e}"))?;
    let App {
        running,
        context,
        error,
        report,
        ..
    } = app;
    // Everything on the GPU goes before the context, whose validation count is read last.
    drop(running);
    if let Some(e) = error {
        return Err(e);
    }
    let context = context.ok_or_else(|| anyhow!("the window never opened"))?;
    let messages = context.validation_errors();
    drop(context);
    if let Some(mut report) = report {
        report.validation_messages = messages;
        println!("{}", report.summary());
        if let Some(path) = &args.stats_json {
            write_json(path, &report)?;
        }
    }
    if messages > 0 {
        bail!("{messages} Vulkan validation message(s) (see the log above)");
    }
    Ok(())
}

/// What `--stats-json` writes (and the summary line printed at exit).
#[derive(Clone, Debug, Default, Serialize)]
struct ViewReport {
    /// Frames presented.
    frames: usize,
    /// Frames per second over the frames after the warm-up.
    fps: f64,
    /// Mean interval between frames (ms) after the warm-up.
    frame_ms_mean: f64,
    /// CPU time of the frame loop beyond waiting for the GPU and the swapchain (ms): input,
    /// camera, egui, recording, submit; mean and median after the warm-up.
    cpu_ms_mean: f64,
    /// Median of the same.
    cpu_ms_median: f64,
    /// The same phases' on-CPU time (the thread's CPU clock, `CLOCK_THREAD_CPUTIME_ID`): not
    /// inflated when other threads (lavapipe's, other processes) preempt the loop. Mean after
    /// the warm-up.
    loop_on_cpu_ms_mean: f64,
    /// Median of the same.
    loop_on_cpu_ms_median: f64,
    /// On-CPU time of the frame loop's thread per frame (ms), waits included: adds the driver
    /// work done inside acquire and present (lavapipe copies the image to the X server there).
    thread_cpu_ms_mean: f64,
    /// The frame loop split into [`PHASES`] (wall ms per frame after the warm-up; waits
    /// included, marked "(wait)"): where `cpu_ms_*` goes.
    cpu_phases: Vec<PhaseStat>,
    /// egui passes per frame (mean after the warm-up): above 1 when egui discarded a pass and ran
    /// the UI again (e.g. an auto-sized window whose size changed), which multiplies its layout cost.
    egui_passes_mean: f64,
    /// Mean GPU time per pass (ms) after the warm-up.
    gpu_ms: Vec<(String, f64)>,
    /// Window size at exit.
    extent: [u32; 2],
    /// Internal render resolution of the last frame.
    internal: [u32; 2],
    /// Render scale of the last frame.
    render_scale: f32,
    /// Swapchain creations (1 + rebuilds after resizes / out-of-date).
    swapchain_creations: u64,
    /// Distinct swapchain sizes in presentation order, with the frames shown at each.
    extents: Vec<([u32; 2], usize)>,
    /// Present mode.
    present_mode: String,
    /// Frames in flight.
    frames_in_flight: usize,
    /// Vulkan validation warnings and errors.
    validation_messages: usize,
}

/// Wall and on-CPU time of one frame-loop phase per frame.
#[derive(Clone, Debug, Serialize)]
struct PhaseStat {
    /// Phase name (see [`PHASES`]).
    name: String,
    /// Mean wall ms per frame.
    mean_ms: f64,
    /// Median wall ms per frame.
    median_ms: f64,
    /// Mean on-CPU ms per frame (the loop thread's CPU clock).
    on_cpu_mean_ms: f64,
    /// Median on-CPU ms per frame.
    on_cpu_median_ms: f64,
}

impl ViewReport {
    fn summary(&self) -> String {
        let passes: Vec<String> = self
            .gpu_ms
            .iter()
            .map(|(n, ms)| format!("{n} {ms:.2} ms"))
            .collect();
        format!(
            "view: {} frames, {:.1} fps ({:.2} ms/frame) at {}x{} (internal {}x{}, scale {:.2}), \
             CPU frame loop {:.3} ms mean / {:.3} ms median (on-CPU {:.3} / {:.3} ms), GPU {}, \
             {} swapchain(s), {}",
            self.frames,
            self.fps,
            self.frame_ms_mean,
            self.extent[0],
            self.extent[1],
            self.internal[0],
            self.internal[1],
            self.render_scale,
            self.cpu_ms_mean,
            self.cpu_ms_median,
            self.loop_on_cpu_ms_mean,
            self.loop_on_cpu_ms_median,
            passes.join(", "),
            self.swapchain_creations,
            self.present_mode
        )
    }
}

/// The winit application: the window and GPU state once resumed.
struct App<'a> {
    args: &'a ViewArgs,
    dag: Svdag,
    stored: Option<voxdag::attr::StoredColors>,
    running: Option<Running>,
    context: Option<Arc<GpuContext>>,
    error: Option<anyhow::Error>,
    report: Option<ViewReport>,
}

/// Per frame-in-flight resources: the render target, the frame constants and a profiler (each
/// reused only after the slot's previous frame finished).
struct SlotResources {
    target: Image,
    frame: RenderFrame,
    profiler: Profiler,
}

/// The open window and everything drawn into it. Fields drop in order: the presenter (waits for
/// the GPU, destroys the swapchain and surface) before the resources, the window last.
struct Running {
    win: GpuWindow,
    slots: Vec<SlotResources>,
    scene: GpuScene,
    renderer: GpuRenderer,
    input: CameraInput,
    user_scale: f32,
    dynamic_scale: bool,
    /// Smoothed GPU ms per rendered pixel of the primary-ray pass (for the dynamic scale).
    ms_per_pixel: Option<f64>,
    last_passes: Vec<PassTiming>,
    last_frame: Option<Instant>,
    frame_ms: f64,
    cpu_ms: f64,
    internal: [u32; 2],
    scale: f32,
    /// Per presented frame: interval since the previous one (ms), CPU loop cost (ms), on-CPU
    /// time of the thread (ms).
    samples: Vec<(f64, f64, f64, f64)>,
    /// Per presented frame: wall ms of each of [`PHASES`].
    phase_samples: Vec<[PhaseTime; PHASES.len()]>,
    /// Times the overlay UI ran (egui passes), in total and per presented frame.
    egui_passes: usize,
    egui_pass_samples: Vec<usize>,
    gpu_sums: Vec<(String, f64, usize)>,
    extents: Vec<([u32; 2], usize)>,
    frames: usize,
    closing: bool,
    /// Exit once this many frames are presented (set by a close request).
    exit_after: Option<usize>,
}

impl ApplicationHandler for App<'_> {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.running.is_some() || self.error.is_some() {
            return;
        }
        match self.open(event_loop) {
            Ok(running) => self.running = Some(running),
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        let Some(running) = self.running.as_mut() else {
            return;
        };
        let result = match event {
            WindowEvent::RedrawRequested => running.redraw(self.args),
            event => {
                running.handle(&event, self.args.frames.is_some());
                Ok(())
            }
        };
        if let Err(e) = result {
            self.error = Some(e);
        }
        let done = self
            .args
            .frames
            .is_some_and(|n| running.frames >= n as usize);
        if running.closing && running.exit_after.is_none() {
            // One more frame after a close request, so a resize just before it is shown.
            running.exit_after = Some(running.frames + 1);
        }
        let closed = running.exit_after.is_some_and(|n| running.frames >= n);
        if self.error.is_some() || done || closed {
            if self.error.is_none() {
                self.report = Some(running.report());
            }
            event_loop.exit();
        }
    }

    fn about_to_wait(&mut self, _: &ActiveEventLoop) {
        if let Some(running) = &self.running {
            running.win.window.request_redraw();
        }
    }
}

impl App<'_> {
    /// Opens the window, the GPU context with presentation, the presenter and the scene.
    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<Running> {
        let args = self.args;
        let win = GpuWindow::open(
            event_loop,
            format!("voxdag view {}", args.file.display()),
            args.size,
            PresenterOptions {
                vsync: !args.no_vsync,
                frames_in_flight: args.frames_in_flight as usize,
            },
        )?;
        let ctx = Arc::clone(&win.ctx);
        self.context = Some(Arc::clone(&ctx));
        let size = win.window.inner_size();
        let presenter = &win.presenter;
        let renderer = GpuRenderer::new(&ctx)?;
        let colors = match &self.stored {
            Some(s) => ColorSource::Chunked(&s.chunks),
            None => ColorSource::Raw(&self.dag.colors),
        };
        let scene = renderer.upload_with(&self.dag, colors)?;
        let mut slots = Vec::new();
        for i in 0..presenter.frames_in_flight() {
            slots.push(SlotResources {
                target: ctx.create_storage_image(
                    &format!("view target {i}"),
                    size.width.max(1),
                    size.height.max(1),
                )?,
                frame: renderer.create_frame()?,
                profiler: Profiler::new(&ctx)?,
            });
        }
        let home = Camera::frame(&self.dag);
        let scene_size = match self.dag.occupied_bounds() {
            Some((min, max)) => (0..3).map(|a| (max[a] - min[a]) as f32).fold(1.0, f32::max),
            None => self.dag.resolution as f32,
        };
        Ok(Running {
            win,
            slots,
            scene,
            renderer,
            input: CameraInput::new(home, scene_size),
            user_scale: if args.screenshot.is_some() {
                1.0
            } else {
                args.render_scale
            },
            dynamic_scale: args.screenshot.is_none(),
            ms_per_pixel: None,
            last_passes: Vec::new(),
            last_frame: None,
            frame_ms: 0.0,
            cpu_ms: 0.0,
            internal: [0, 0],
            scale: 1.0,
            samples: Vec::new(),
            phase_samples: Vec::new(),
            egui_passes: 0,
            egui_pass_samples: Vec::new(),
            gpu_sums: Vec::new(),
            extents: Vec::new(),
            frames: 0,
            closing: false,
            exit_after: None,
        })
    }
}

impl Running {
    /// Input: egui first, then the camera (ignored in scripted runs, so `--frames` renders the
    /// default camera whatever the pointer does).
    fn handle(&mut self, event: &WindowEvent, scripted: bool) {
        let consumed = self
            .win
            .egui_state
            .on_window_event(&self.win.window, event)
            .consumed;
        match event {
            WindowEvent::CloseRequested => self.closing = true,
            WindowEvent::Resized(size) => self.win.presenter.resize([size.width, size.height]),
            _ if consumed || scripted => {}
            WindowEvent::KeyboardInput { event, .. } => {
                let PhysicalKey::Code(code) = event.physical_key else {
                    return;
                };
                let pressed = event.state == ElementState::Pressed;
                match code {
                    KeyCode::Escape if pressed => self.closing = true,
                    KeyCode::Home if pressed => self.input.go_home(),
                    _ if pressed => {
                        self.input.keys.insert(code);
                    }
                    _ => {
                        self.input.keys.remove(&code);
                    }
                }
            }
            WindowEvent::ModifiersChanged(m) => self.input.fast = m.state().shift_key(),
            WindowEvent::MouseInput { state, button, .. } => {
                let pressed = *state == ElementState::Pressed;
                match button {
                    MouseButton::Left | MouseButton::Middle => self.input.orbit_drag = pressed,
                    MouseButton::Right => self.input.look_drag = pressed,
                    _ => {}
                }
            }
            WindowEvent::CursorMoved { position, .. } => self.input.cursor_moved(*position),
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => *y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                // Shift + wheel: fly speed, as in the editor.
                if self.input.fast {
                    self.input.scale_fly_speed(lines);
                } else {
                    self.input.zoom(lines);
                }
            }
            WindowEvent::Focused(false) => self.input.keys.clear(),
            _ => {}
        }
    }

    /// The render scale of this frame: the user's, or lower while the camera moves so that the
    /// primary-ray pass stays near `MOTION_TARGET_MS`.
    fn frame_scale(&self, extent: [u32; 2]) -> f32 {
        if !self.dynamic_scale || !self.input.moving() {
            return self.user_scale;
        }
        let Some(ms_per_pixel) = self.ms_per_pixel else {
            return self.user_scale;
        };
        let full = ms_per_pixel * extent[0] as f64 * extent[1] as f64;
        let scale = (MOTION_TARGET_MS / full.max(1e-9)).sqrt() as f32;
        scale.clamp(MIN_SCALE, self.user_scale)
    }

    /// One frame: wait for a slot, camera, overlay, record the render and present it.
    fn redraw(&mut self, args: &ViewArgs) -> Result<()> {
        let frame_start = PhaseClock::start();
        let presenter_before = presenter_times(self.win.presenter.stats());
        let mut phases = [PhaseTime::default(); PHASES.len()];
        let mut clock = frame_start;
        let mut lap = |phase: usize| phases[phase] += clock.lap();
        let dt = self
            .last_frame
            .map_or(0.0, |t| t.elapsed().as_secs_f32().min(0.1));
        let Some(frame) = self.win.presenter.begin_frame()? else {
            return Ok(());
        };
        // Slot wait + acquire, split below from the presenter's times.
        lap(0);
        // The slot's previous frame has finished: its pass times are the latest complete ones.
        let passes = {
            let profiler = &mut self.slots[frame.index].profiler;
            let passes = profiler.resolve()?;
            profiler.clear();
            passes
        };
        if !passes.is_empty() {
            self.note_passes(&passes);
            self.last_passes = passes;
        }
        lap(2);
        let extent = frame.extent;
        let slot = &mut self.slots[frame.index];
        if slot.target.width() != extent[0] || slot.target.height() != extent[1] {
            // Resized: the slot's old target belongs to a finished frame.
            slot.target = self.win.ctx.create_storage_image(
                &format!("view target {}", frame.index),
                extent[0],
                extent[1],
            )?;
        }
        if args.frames.is_none() {
            self.input.fly(dt);
        }
        let scale = self.frame_scale(extent);
        let internal = [
            ((extent[0] as f32 * scale).round() as u32).clamp(1, extent[0]),
            ((extent[1] as f32 * scale).round() as u32).clamp(1, extent[1]),
        ];
        self.scale = scale;
        self.internal = internal;
        let settings = RenderSettings::new(internal[0], internal[1], self.input.camera);
        lap(3);

        let passes_before = self.egui_passes;
        let raw_input = self.win.egui_state.take_egui_input(&self.win.window);
        let egui = self.win.egui.clone();
        let output = egui.run_ui(raw_input, |ui| self.overlay_ui(ui, extent));
        self.win
            .egui_state
            .handle_platform_output(&self.win.window, output.platform_output);
        lap(4);
        let primitives = self
            .win
            .egui
            .tessellate(output.shapes, output.pixels_per_point);
        lap(5);

        let last = args.frames.is_some_and(|n| self.frames + 1 >= n as usize);
        let screenshot = last && args.screenshot.is_some();
        let slot = &mut self.slots[frame.index];
        let mut cmd = self.win.ctx.begin_commands("view frame")?;
        self.renderer.record(
            &mut cmd,
            &self.scene,
            &mut slot.frame,
            &settings,
            &slot.target,
            None,
            Some(&mut slot.profiler),
        )?;
        lap(6);
        self.win.presenter.end_frame(
            cmd,
            &slot.target,
            internal,
            Some(OverlayFrame {
                primitives: &primitives,
                textures_delta: output.textures_delta,
                pixels_per_point: output.pixels_per_point,
            }),
            screenshot,
            Some(&mut slot.profiler),
        )?;
        self.frames += 1;
        match self.extents.last_mut() {
            Some((e, n)) if *e == extent => *n += 1,
            _ => self.extents.push((extent, 1)),
        }
        // end_frame, split below from the presenter's times.
        lap(8);
        let total = clock - frame_start;
        let now = clock.instant();
        // end_frame and begin_frame's parts, from the presenter's counters.
        let presenter_after = presenter_times(self.win.presenter.stats());
        for (phase, i) in [(0, 0), (1, 1), (7, 2), (8, 3), (9, 4), (10, 5)] {
            phases[phase] = presenter_after[i] - presenter_before[i];
        }
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        let timed = phases[..11]
            .iter()
            .fold(PhaseTime::default(), |mut sum, p| {
                sum += *p;
                sum
            });
        phases[11] = total - timed;
        let loop_time = (0..PHASES.len()).filter(|i| !WAIT_PHASES.contains(i)).fold(
            PhaseTime::default(),
            |mut sum, i| {
                sum += phases[i];
                sum
            },
        );
        if let Some(prev) = self.last_frame {
            let interval = ms(now - prev);
            self.frame_ms = interval;
            self.samples.push((
                interval,
                ms(loop_time.wall),
                ms(loop_time.cpu),
                ms(total.cpu),
            ));
            self.phase_samples.push(phases);
            self.egui_pass_samples
                .push(self.egui_passes - passes_before);
        }
        self.cpu_ms = ms(loop_time.wall);
        self.last_frame = Some(now);
        if screenshot {
            let path = args.screenshot.as_ref().expect("checked above");
            let (width, height, rgba) = self
                .win
                .presenter
                .take_screenshot()?
                .ok_or_else(|| anyhow!("the screenshot frame recorded no copy"))?;
            let image = RenderOutput {
                width,
                height,
                rgba,
                hits: Vec::new(),
            };
            image.save_png(path)?;
            println!("{}: {width}x{height} screenshot", path.display());
        }
        Ok(())
    }

    /// Accumulates pass times for the report and the dynamic scale's cost model.
    fn note_passes(&mut self, passes: &[PassTiming]) {
        if let Some(p) = passes.iter().find(|p| p.name == "primary rays") {
            let pixels = (self.internal[0] as f64 * self.internal[1] as f64).max(1.0);
            let sample = p.gpu_ms / pixels;
            self.ms_per_pixel = Some(match self.ms_per_pixel {
                Some(old) => 0.8 * old + 0.2 * sample,
                None => sample,
            });
        }
        if self.frames <= WARMUP_FRAMES {
            return;
        }
        for p in passes {
            match self.gpu_sums.iter_mut().find(|s| s.0 == p.name) {
                Some(s) => {
                    s.1 += p.gpu_ms;
                    s.2 += 1;
                }
                None => self.gpu_sums.push((p.name.clone(), p.gpu_ms, 1)),
            }
        }
    }

    /// The egui overlay: frame rate, resolution, render scale, GPU pass times, controls.
    fn overlay_ui(&mut self, ui: &mut egui::Ui, extent: [u32; 2]) {
        self.egui_passes += 1;
        let ctx = ui.ctx().clone();
        egui::Window::new("voxdag")
            .default_pos([8.0, 8.0])
            .resizable(false)
            .show(&ctx, |ui| {
                let fps = if self.frame_ms > 0.0 {
                    1e3 / self.frame_ms
                } else {
                    0.0
                };
                ui.label(format!("{fps:.1} fps, {:.2} ms/frame", self.frame_ms));
                ui.label(format!("CPU frame loop {:.3} ms", self.cpu_ms));
                ui.label(format!(
                    "internal {}x{} of {}x{} (scale {:.2})",
                    self.internal[0], self.internal[1], extent[0], extent[1], self.scale
                ));
                ui.add(
                    egui::Slider::new(&mut self.user_scale, MIN_SCALE..=1.0).text("render scale"),
                );
                ui.checkbox(&mut self.dynamic_scale, "lower scale while moving");
                ui.label(format!(
                    "{}, {} frames in flight",
                    self.win.presenter.stats().present_mode,
                    self.win.presenter.frames_in_flight()
                ));
                ui.separator();
                ui.label("GPU passes (last frame)");
                for p in &self.last_passes {
                    ui.label(format!("  {}: {:.2} ms", p.name, p.gpu_ms));
                }
                ui.separator();
                ui.label("drag L/M: orbit, wheel: zoom, drag R: look");
                ui.label(
                    "WASD/QE: fly (Shift: fast; Shift + wheel: speed), Home: frame, Esc: quit",
                );
            });
    }

    /// The statistics of the run.
    fn report(&self) -> ViewReport {
        let kept: Vec<(f64, f64, f64, f64)> =
            self.samples.iter().skip(WARMUP_FRAMES).copied().collect();
        let kept = if kept.is_empty() {
            self.samples.clone()
        } else {
            kept
        };
        let n = kept.len().max(1) as f64;
        let frame_ms_mean = kept.iter().map(|s| s.0).sum::<f64>() / n;
        let mut cpu: Vec<f64> = kept.iter().map(|s| s.1).collect();
        cpu.sort_by(f64::total_cmp);
        let mean_median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
            (mean, v.get(v.len() / 2).copied().unwrap_or(0.0))
        };
        let loop_on_cpu = mean_median(kept.iter().map(|s| s.2).collect());
        let phase_rows: Vec<&[PhaseTime; PHASES.len()]> =
            if self.phase_samples.len() > WARMUP_FRAMES {
                self.phase_samples.iter().skip(WARMUP_FRAMES).collect()
            } else {
                self.phase_samples.iter().collect()
            };
        let cpu_phases = PHASES
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let ms = |d: Duration| d.as_secs_f64() * 1e3;
                let (mean_ms, median_ms) =
                    mean_median(phase_rows.iter().map(|p| ms(p[i].wall)).collect());
                let (on_cpu_mean_ms, on_cpu_median_ms) =
                    mean_median(phase_rows.iter().map(|p| ms(p[i].cpu)).collect());
                PhaseStat {
                    name: name.to_string(),
                    mean_ms,
                    median_ms,
                    on_cpu_mean_ms,
                    on_cpu_median_ms,
                }
            })
            .collect();
        let stats = self.win.presenter.stats();
        ViewReport {
            frames: self.frames,
            fps: if frame_ms_mean > 0.0 {
                1e3 / frame_ms_mean
            } else {
                0.0
            },
            frame_ms_mean,
            cpu_ms_mean: cpu.iter().sum::<f64>() / n,
            cpu_ms_median: cpu.get(cpu.len() / 2).copied().unwrap_or(0.0),
            loop_on_cpu_ms_mean: loop_on_cpu.0,
            loop_on_cpu_ms_median: loop_on_cpu.1,
            thread_cpu_ms_mean: kept.iter().map(|s| s.3).sum::<f64>() / n,
            cpu_phases,
            egui_passes_mean: {
                let kept: Vec<usize> = self
                    .egui_pass_samples
                    .iter()
                    .skip(WARMUP_FRAMES)
                    .copied()
                    .collect();
                kept.iter().sum::<usize>() as f64 / kept.len().max(1) as f64
            },
            gpu_ms: self
                .gpu_sums
                .iter()
                .map(|(name, sum, count)| (name.clone(), sum / *count as f64))
                .collect(),
            extent: self.win.presenter.extent(),
            internal: self.internal,
            render_scale: self.scale,
            swapchain_creations: stats.swapchain_creations,
            extents: self.extents.clone(),
            present_mode: stats.present_mode.clone(),
            frames_in_flight: self.win.presenter.frames_in_flight(),
            validation_messages: 0,
        }
    }
}
