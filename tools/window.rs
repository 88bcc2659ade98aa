//! The window code shared by `voxdag view` and `voxdag editor`: the orbit / fly camera driven by
//! input, and opening a window with its GPU context, presenter and egui state.

use std::collections::HashSet;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use glam::Vec3;
use raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use voxdag::gpu::{GpuContext, GpuOptions, Presenter, PresenterOptions, Surface};
use voxdag::render::Camera;
use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::event_loop::ActiveEventLoop;
use winit::keyboard::KeyCode;
use winit::window::Window;

/// The camera counts as moving this long after the last input.
const MOTION_HOLD: Duration = Duration::from_millis(300);
/// Smallest render scale (slider and dynamic scale).
pub const MIN_SCALE: f32 = 0.1;

/// The display named by `DISPLAY`, or the one-line error of a headless machine.
pub fn require_display(command: &str) -> Result<String> {
    let display = std::env::var("DISPLAY").unwrap_or_default();
    if display.is_empty() {
        anyhow::bail!(
            "cannot open a window: no display (DISPLAY is not set); `voxdag {command}` needs an X \
             server (on a headless machine: xvfb-run voxdag {command} ...)"
        );
    }
    Ok(display)
}

/// An open window with its GPU context, presenter and egui state. Fields drop in order: the
/// presenter (surface) before the window.
pub struct GpuWindow {
    /// Swapchain, frames in flight, blit and overlay.
    pub presenter: Presenter,
    /// The GPU context (with presentation).
    pub ctx: Arc<GpuContext>,
    /// egui's winit glue.
    pub egui_state: egui_winit::State,
    /// The egui context.
    pub egui: egui::Context,
    /// The window.
    pub window: Arc<Window>,
}

impl GpuWindow {
    /// Opens a `size` window titled `title`, the GPU context presenting to it and the presenter.
    pub fn open(
        event_loop: &ActiveEventLoop,
        title: String,
        size: (u32, u32),
        options: PresenterOptions,
    ) -> Result<GpuWindow> {
        let window = Arc::new(
            event_loop
                .create_window(
                    Window::default_attributes()
                        .with_title(title)
                        .with_inner_size(PhysicalSize::new(size.0, size.1)),
                )
                .context("creating the window")?,
        );
        let display = window.display_handle().context("display handle")?.as_raw();
        let handle = window.window_handle().context("window handle")?.as_raw();
        let ctx = GpuContext::new(&GpuOptions {
            display: Some(display),
            ..GpuOptions::default()
        })?;
        // SAFETY: the window outlives the presenter (and with it the surface): `GpuWindow`
        // drops the presenter first.
        let surface = unsafe { Surface::new(&ctx, display, handle)? };
        let size = window.inner_size();
        let presenter = Presenter::new(surface, [size.width, size.height], options)
            .map_err(|e| anyhow!("presenter: {e}"))?;
        let egui = egui::Context::default();
        let egui_state = egui_winit::State::new(
            egui.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            None,
        );
        Ok(GpuWindow {
            presenter,
            ctx,
            egui_state,
            egui,
            window,
        })
    }
}

/// Slowest fly speed factor ([`CameraInput::fly_speed`]).
pub const MIN_FLY_SPEED: f32 = 1.0 / 64.0;
/// Fastest fly speed factor.
pub const MAX_FLY_SPEED: f32 = 64.0;

/// Orbit and fly camera state driven by input.
pub struct CameraInput {
    /// The camera rendered this frame.
    pub camera: Camera,
    /// The camera the home key goes back to.
    pub home: Camera,
    /// Scene extent in voxels: scales fly speed and the zoom limit.
    pub scene_size: f32,
    /// Orbiting while the pointer moves.
    pub orbit_drag: bool,
    /// Turning the view around the eye while the pointer moves.
    pub look_drag: bool,
    /// Last pointer position in the window.
    pub cursor: Option<PhysicalPosition<f64>>,
    /// Keys held.
    pub keys: HashSet<KeyCode>,
    /// Shift held: fly 4x faster.
    pub fast: bool,
    /// Fly speed factor (the editor's Shift + wheel), [`MIN_FLY_SPEED`]..=[`MAX_FLY_SPEED`].
    pub fly_speed: f32,
    last_input: Option<Instant>,
}

impl CameraInput {
    /// Starts at `home`, for a scene `scene_size` voxels across.
    pub fn new(home: Camera, scene_size: f32) -> CameraInput {
        CameraInput {
            camera: home,
            home,
            scene_size,
            orbit_drag: false,
            look_drag: false,
            cursor: None,
            keys: HashSet::new(),
            fast: false,
            fly_speed: 1.0,
            last_input: None,
        }
    }

    /// Back to the home camera.
    pub fn go_home(&mut self) {
        self.camera = self.home;
        self.touch();
    }

    /// Pointer moved to `position`: drags the camera when a drag is on.
    pub fn cursor_moved(&mut self, position: PhysicalPosition<f64>) {
        if let Some(last) = self.cursor {
            if self.orbit_drag || self.look_drag {
                let (dx, dy) = (position.x - last.x, position.y - last.y);
                self.drag(dx as f32, dy as f32);
            }
        }
        self.cursor = Some(position);
    }

    /// Marks the camera as moving now (for the dynamic render scale).
    pub fn touch(&mut self) {
        self.last_input = Some(Instant::now());
    }

    /// Whether the camera moved recently or a fly key is held.
    pub fn moving(&self) -> bool {
        const FLY: [KeyCode; 6] = [
            KeyCode::KeyW,
            KeyCode::KeyA,
            KeyCode::KeyS,
            KeyCode::KeyD,
            KeyCode::KeyQ,
            KeyCode::KeyE,
        ];
        FLY.iter().any(|k| self.keys.contains(k))
            || self.last_input.is_some_and(|t| t.elapsed() < MOTION_HOLD)
    }

    /// Drag by (dx, dy) pixels: orbit around the target, or turn the view around the eye.
    pub fn drag(&mut self, dx: f32, dy: f32) {
        let (eye, target) = (Vec3::from(self.camera.eye), Vec3::from(self.camera.target));
        let k = 0.005;
        if self.orbit_drag {
            let offset = rotate(eye - target, -dx * k, dy * k);
            self.camera.eye = (target + offset).to_array();
        } else if self.look_drag {
            let dir = rotate(target - eye, -dx * k, -dy * k);
            self.camera.target = (eye + dir).to_array();
        }
        self.touch();
    }

    /// Wheel: move the eye towards (positive) or away from the target.
    pub fn zoom(&mut self, lines: f32) {
        let (eye, target) = (Vec3::from(self.camera.eye), Vec3::from(self.camera.target));
        let offset = (eye - target) * 0.9f32.powf(lines);
        if offset.length() > 1.0 {
            self.camera.eye = (target + offset).to_array();
        }
        self.touch();
    }

    /// Multiplies the fly speed by 1.25 per wheel line (`lines` < 0: slower), clamped.
    pub fn scale_fly_speed(&mut self, lines: f32) {
        self.fly_speed = (self.fly_speed * 1.25f32.powf(lines)).clamp(MIN_FLY_SPEED, MAX_FLY_SPEED);
    }

    /// Fly with WASD (forward/left/back/right) and Q/E (down/up) for `dt` seconds.
    pub fn fly(&mut self, dt: f32) {
        let axis = |plus: KeyCode, minus: KeyCode| {
            self.keys.contains(&plus) as i32 as f32 - self.keys.contains(&minus) as i32 as f32
        };
        let (f, r, u) = (
            axis(KeyCode::KeyW, KeyCode::KeyS),
            axis(KeyCode::KeyD, KeyCode::KeyA),
            axis(KeyCode::KeyE, KeyCode::KeyQ),
        );
        if f == 0.0 && r == 0.0 && u == 0.0 {
            return;
        }
        let (eye, target) = (Vec3::from(self.camera.eye), Vec3::from(self.camera.target));
        let forward = (target - eye).normalize_or_zero();
        let right = forward.cross(Vec3::Y).normalize_or_zero();
        let speed = self.scene_size * 0.4 * self.fly_speed * if self.fast { 4.0 } else { 1.0 };
        let step = (forward * f + right * r + Vec3::Y * u) * speed * dt;
        self.camera.eye = (eye + step).to_array();
        self.camera.target = (target + step).to_array();
        self.touch();
    }
}

/// Rotates `v` by `yaw` around +y and raises its elevation by `pitch` (clamped short of the
/// poles), keeping its length.
fn rotate(v: Vec3, yaw: f32, pitch: f32) -> Vec3 {
    let r = v.length();
    if r == 0.0 {
        return v;
    }
    let azimuth = v.x.atan2(v.z) + yaw;
    let elevation = ((v.y / r).clamp(-1.0, 1.0).asin() + pitch).clamp(-1.55, 1.55);
    r * Vec3::new(
        elevation.cos() * azimuth.sin(),
        elevation.sin(),
        elevation.cos() * azimuth.cos(),
    )
}
