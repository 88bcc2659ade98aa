//! `voxdag editor`: a real-time voxel editor. The scene lives in a [`GpuHashDag`] (nine slab hash
//! tables on the GPU) that the renderer traverses in place (`GpuRenderer::bind_hash_dag`); sphere
//! and cube tools edit it under the cursor, with undo / redo, egui panels and headless hooks
//! (status file, replays, save, screenshot) for the tests. See docs/editor.md.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use rustc_hash::FxHashMap;
use serde::Serialize;
use voxdag::attr::Materials;
use voxdag::dag::{Svdag, VdagFile};
use voxdag::edit::gpu::{GpuHashDag, GpuHashDagConfig, HashDagImage};
use voxdag::edit::item::{NodePtr, Root};
use voxdag::edit::replay::{Action, Replay};
use voxdag::edit::tool::Tool;
use voxdag::edit::walk::{self, MaterialCounts};
use voxdag::gpu::{
    Buffer, GpuContext, Image, MemLocation, OverlayFrame, PassTiming, PresenterOptions, Profiler,
};
use voxdag::hash::HashVariant;
use voxdag::render::gpu::{GpuRenderer, GpuScene, Palette, RenderFrame};
use voxdag::render::pathtrace::DEFAULT_BOUNCES;
use voxdag::render::{Camera, FirstHit, RenderOutput, RenderSettings};
use voxdag::scene::{self, ImportOptions};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, ModifiersState, PhysicalKey};
use winit::window::WindowId;

mod files;
mod record;

use crate::commands::{check_output, progress_bar, write_json};
use crate::edit::TableArg;
use crate::view::MOTION_TARGET_MS;
use crate::window::{require_display, CameraInput, GpuWindow, MIN_SCALE};

mod brush;
mod panels;
mod pt;

use brush::CopyState;
pub use brush::ToolKind;
use panels::PanelState;
pub use pt::RenderMode;
use pt::{PtKey, PtLighting, PtState, MAX_EDITOR_BOUNCES, MAX_FRAME_SPP};

/// Largest tool radius in voxels (slider and wheel).
const MAX_RADIUS: f32 = 256.0;
/// Wall time per frame the dynamic scale aims at while the button edits (16.7 frames/s).
const EDIT_FRAME_TARGET_MS: f64 = 60.0;
/// Least time between two profiled edits (the Profiler panel's kernel breakdown) unless a trace
/// records.
const EDIT_PROFILE_INTERVAL: Duration = Duration::from_secs(1);
/// Least render time the dynamic scale gives an editing frame (the scale's floor may be above).
const EDIT_RENDER_MIN_MS: f64 = 5.0;
/// Colours of the 16 materials (editable in the Tools panel) where the scene has no palette.
/// Material 0 is the renderer's grey (linear 0.6) so a geometry-only scene looks as before.
const DEFAULT_PALETTE: Palette = [
    [203, 203, 203],
    [230, 80, 70],
    [240, 160, 60],
    [240, 220, 80],
    [120, 200, 90],
    [60, 160, 110],
    [70, 190, 200],
    [70, 120, 220],
    [120, 90, 210],
    [190, 100, 200],
    [230, 130, 170],
    [150, 110, 80],
    [90, 90, 90],
    [40, 40, 40],
    [250, 250, 250],
    [170, 200, 240],
];

/// Arguments of `voxdag editor`.
#[derive(Args)]
pub struct EditorArgs {
    /// The scene: a .vdag file, or a mesh / .vox file voxelized at --resolution.
    scene: PathBuf,
    /// Grid resolution for a mesh (power of two).
    #[arg(long)]
    resolution: Option<u32>,
    /// Window size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = crate::commands::parse_size)]
    size: (u32, u32),
    /// Internal resolution as a fraction of the window (0.1..=1).
    #[arg(long, default_value_t = 1.0)]
    render_scale: f32,
    /// How the scene is drawn at start (Settings panel, P toggles): primary rays + shadows, or
    /// progressive path tracing.
    #[arg(long, value_enum, default_value_t = RenderMode::Raster)]
    render_mode: RenderMode,
    /// Path tracing: diffuse bounces per path.
    #[arg(long, default_value_t = DEFAULT_BOUNCES, value_parser = clap::value_parser!(u32).range(0..=MAX_EDITOR_BOUNCES as i64))]
    bounces: u32,
    /// Path tracing: constant environment radiance "r,g,b" (as `render --pt --env`).
    #[arg(long, default_value = "1,1,1", value_parser = crate::pathtrace::parse_floats::<3>, allow_hyphen_values = true)]
    env: [f32; 3],
    /// Path tracing: a sun "x,y,z,intensity", the direction towards it (as `render --pt
    /// --sun`; the Settings panel turns it and switches it on and off).
    #[arg(long, value_parser = crate::pathtrace::parse_floats::<4>, allow_hyphen_values = true)]
    sun: Option<[f32; 4]>,
    /// Path tracing: samples per pixel added each frame.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=MAX_FRAME_SPP as i64))]
    spp: u32,
    /// Path tracing: the accumulation stops at this many samples per pixel (a --screenshot is
    /// taken once they are in).
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..))]
    max_samples: u32,
    /// Present without waiting for vertical blank.
    #[arg(long)]
    no_vsync: bool,
    /// Frames the CPU may record ahead of the GPU.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=4))]
    frames_in_flight: u32,
    /// The tool selected at start.
    #[arg(long, value_enum, default_value_t = ToolKind::SphereAdd)]
    tool: ToolKind,
    /// Tool radius in voxels at start.
    #[arg(long, default_value_t = 8.0)]
    radius: f32,
    /// Material (0..16) of added voxels at start.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..16))]
    material: u8,
    /// Undo steps kept.
    #[arg(long, default_value_t = 64)]
    undo_depth: usize,
    /// Slab layout of the hash tables at start (switchable in the Settings panel); Ticket
    /// Board has the fastest edits in docs/editing-gpu.md.
    #[arg(long, value_enum, default_value_t = TableArg::TicketBoard)]
    table: TableArg,
    /// Record a Chrome trace of the first --trace-frames frames to this file (also from the
    /// Profiler panel).
    #[arg(long)]
    trace: Option<PathBuf>,
    /// Frames the --trace recording covers.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..=panels::MAX_TRACE_FRAMES as i64))]
    trace_frames: u32,
    /// Write frame and edit-latency statistics (JSON) here at exit (docs/editor.md,
    /// "Benchmark").
    #[arg(long)]
    stats_json: Option<PathBuf>,
    /// Rewrite this JSON file atomically every frame (frame, voxels, undo_depth, ...).
    #[arg(long)]
    status_file: Option<PathBuf>,
    /// Play this HashDAG replay (CSV), one edit per frame.
    #[arg(long)]
    replay: Option<PathBuf>,
    /// Depth the replay was recorded at (default: the scene's).
    #[arg(long)]
    replay_depth: Option<u32>,
    /// Exit once the replay is done (after --save and --screenshot).
    #[arg(long, requires = "replay")]
    exit_after_replay: bool,
    /// Where Ctrl+S and the Save button write the scene (.vdag, svdag32); also written after a
    /// replay with --exit-after-replay.
    #[arg(long)]
    save: Option<PathBuf>,
    /// Save the first frame after the replay (render scale 1, no overlay; path tracing: the
    /// frame with --max-samples samples) as a PNG.
    #[arg(long, requires = "exit_after_replay")]
    screenshot: Option<PathBuf>,
    /// Autosave, recovery, recording and replay pace (tools/editor/files.rs).
    #[command(flatten)]
    files: files::FileArgs,
}

/// `voxdag editor`.
pub fn editor(args: &EditorArgs) -> Result<()> {
    if !(MIN_SCALE..=1.0).contains(&args.render_scale) {
        bail!(
            "--render-scale {} out of range ({MIN_SCALE}..=1)",
            args.render_scale
        );
    }
    if !(args.radius > 0.0 && args.radius <= MAX_RADIUS) {
        bail!("--radius {} out of range (0, {MAX_RADIUS}]", args.radius);
    }
    let lighting = PtLighting::new(args.env, args.sun)?;
    for path in [
        &args.status_file,
        &args.save,
        &args.screenshot,
        &args.trace,
        &args.stats_json,
        &args.files.record,
    ]
    .into_iter()
    .flatten()
    {
        check_output(path)?;
    }
    let display = require_display("editor")?;
    let (dag, materials) = load_scene(&args.scene, args.resolution)?;
    let steps = match &args.replay {
        Some(path) => {
            let replay = Replay::load(path)?;
            let depth = args.replay_depth.unwrap_or(dag.resolution.trailing_zeros());
            let steps = replay.steps(dag.resolution, depth, args.material)?;
            record::Playlist::new(&replay, steps)
        }
        None => record::Playlist::default(),
    };
    let event_loop = EventLoop::new()
        .map_err(|e| anyhow!("cannot open a window on display {display:?}: {e}"))?;
    event_loop.set_control_flow(ControlFlow::Poll);
    let mut app = App {
        args,
        initial: Some((dag, materials)),
        lighting,
        steps,
        running: None,
        context: None,
        error: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| anyhow!("window event loop: {e}"))?;
    let App {
        running,
        context,
        error,
        ..
    } = app;
    if let (Some(path), Some(r)) = (&args.stats_json, &running) {
        let stats = r.stats_json(args);
        write_json(path, &stats)?;
        let ms = |key: &str, q: &str| stats[key][q].as_f64().unwrap_or(0.0);
        println!(
            "{}: {} frames, {:.1} fps while editing, edit latency p50 {:.1} ms p95 {:.1} ms \
             (bound p50 {:.1} ms p95 {:.1} ms)",
            path.display(),
            stats["frames"],
            stats["editing_fps"].as_f64().unwrap_or(0.0),
            ms("edit_latency_ms", "p50"),
            ms("edit_latency_ms", "p95"),
            ms("edit_latency_bound_ms", "p50"),
            ms("edit_latency_bound_ms", "p95"),
        );
    }
    drop(running);
    if let Some(e) = error {
        return Err(e);
    }
    let context = context.ok_or_else(|| anyhow!("the window never opened"))?;
    let messages = context.validation_errors();
    drop(context);
    if messages > 0 {
        bail!("{messages} Vulkan validation message(s) (see the log above)");
    }
    Ok(())
}

/// Loads a `.vdag` file with its materials (`build --materials`), or voxelizes a mesh /
/// `.vox` file at `resolution`. Colours are dropped: the GPU hash DAG holds materials, and a
/// scene without them starts with every voxel of material 0.
fn load_scene(path: &Path, resolution: Option<u32>) -> Result<(Svdag, Option<Materials>)> {
    let is_vdag = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vdag"));
    let (mut dag, materials) = if is_vdag {
        if resolution.is_some() {
            bail!("--resolution is for meshes; {} is a .vdag", path.display());
        }
        // Colours are dropped: chunked ones are checked but never decoded all at once.
        let mut file = VdagFile::load_encoded_colors(path)?;
        let materials = file.materials.take();
        (file.into_svdag(path)?, materials)
    } else {
        let options = ImportOptions {
            resolution,
            vox_scale: 1,
            texture_override: None,
        };
        let voxels = scene::import_in(path, &options, None, &progress_bar(true))?;
        (Svdag::from_voxels(&voxels)?, None)
    };
    dag.colors.clear();
    Ok((dag, materials))
}

/// The tool of a number key (1..7).
fn tool_key(code: KeyCode) -> Option<usize> {
    const KEYS: [KeyCode; 7] = [
        KeyCode::Digit1,
        KeyCode::Digit2,
        KeyCode::Digit3,
        KeyCode::Digit4,
        KeyCode::Digit5,
        KeyCode::Digit6,
        KeyCode::Digit7,
    ];
    KEYS.iter().position(|&k| k == code)
}

/// The winit application.
struct App<'a> {
    args: &'a EditorArgs,
    /// The scene until the window opens.
    initial: Option<(Svdag, Option<Materials>)>,
    /// Path tracing's light of `--env` / `--sun` (checked before the window opens).
    lighting: PtLighting,
    steps: record::Playlist,
    running: Option<Running>,
    context: Option<Arc<GpuContext>>,
    error: Option<anyhow::Error>,
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
                running.handle(&event);
                Ok(())
            }
        };
        if let Err(e) = result {
            self.error = Some(e);
        }
        if self.error.is_some() || running.exit {
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
    /// Opens the window, loads the scene into the GPU hash DAG and binds it for rendering.
    fn open(&mut self, event_loop: &ActiveEventLoop) -> Result<Running> {
        let args = self.args;
        let win = GpuWindow::open(
            event_loop,
            format!("voxdag editor {}", args.scene.display()),
            args.size,
            PresenterOptions {
                vsync: !args.no_vsync,
                frames_in_flight: args.frames_in_flight as usize,
            },
        )?;
        let ctx = Arc::clone(&win.ctx);
        self.context = Some(Arc::clone(&ctx));
        let renderer = GpuRenderer::new(&ctx)?;
        let (svdag, materials) = self.initial.take().expect("opened once");
        let doc = Document::load(
            &ctx,
            &renderer,
            &svdag,
            materials,
            args.scene.clone(),
            args.undo_depth,
            args.table.variant(),
        )?;
        let mut slots = Vec::new();
        for _ in 0..win.presenter.frames_in_flight() {
            slots.push(Slot {
                target: None,
                first_hits: None,
                frame: renderer.create_frame()?,
                profiler: Profiler::new(&ctx)?,
                view: None,
                edit_input: None,
            });
        }
        let home = Camera::frame(&svdag);
        let input = CameraInput::new(home, scene_size(&svdag));
        let replaying = !self.steps.is_empty() || args.replay.is_some();
        let files = files::FileState::new(&args.files, &args.scene, svdag.resolution)?;
        let mut running = Running {
            win,
            slots,
            doc,
            renderer,
            edit_profiler: Profiler::new(&ctx)?,
            ctx,
            input,
            modifiers: ModifiersState::empty(),
            tool: args.tool,
            radius: args.radius,
            material: args.material,
            copy: CopyState::default(),
            palette_changed: false,
            painting: false,
            click: None,
            hover: None,
            user_scale: if args.screenshot.is_some() {
                1.0
            } else {
                args.render_scale
            },
            dynamic_scale: args.screenshot.is_none() && !replaying,
            ms_per_pixel: None,
            internal: [0, 0],
            scale: 1.0,
            last_passes: Vec::new(),
            last_edit: None,
            profiled_edit: None,
            edit_input: None,
            last_frame: None,
            frame_ms: 0.0,
            frame_rest_ms: None,
            frames: 0,
            steps: std::mem::take(&mut self.steps),
            replay_done: !replaying,
            wrap_up: false,
            render_mode: args.render_mode,
            pt: None,
            bounces: args.bounces,
            spp: args.spp,
            max_samples: args.max_samples,
            lighting: self.lighting,
            message: None,
            save_path: args
                .save
                .clone()
                .unwrap_or_else(|| args.scene.with_extension("edited.vdag"))
                .display()
                .to_string(),
            files,
            exit: false,
            clicks: 0,
            ui_clicks: 0,
            ui_keys: 0,
            ui: PanelState::new(!args.no_vsync),
            traces_written: 0,
            stats: FrameStats::default(),
            last_pointer: None,
            redraw_start: None,
        };
        if let Some(path) = &args.trace {
            running.start_trace(path.clone(), args.trace_frames)?;
        }
        Ok(running)
    }
}

/// The largest side of the occupied box, in voxels (fly speed).
fn scene_size(dag: &Svdag) -> f32 {
    match dag.occupied_bounds() {
        Some((min, max)) => (0..3).map(|a| (max[a] - min[a]) as f32).fold(1.0, f32::max),
        None => dag.resolution as f32,
    }
}

/// The scene being edited: the hash DAG, the renderer's binding of it and what the panels
/// show of it. The binding is declared first so it drops before the tables it reads.
struct Document {
    scene: GpuScene,
    dag: GpuHashDag,
    /// Which binding `scene` is (`next_binding`): a new one restarts path tracing.
    binding: u64,
    path: PathBuf,
    /// The colour of each material (the renderer's palette; edited in the Tools panel).
    palette: Palette,
    /// Palette entries of the loaded file (0: it had no materials). A save keeps at least
    /// these, and a scene without them is saved without materials unless one was added.
    file_palette: usize,
    /// Undo and redo steps available.
    undo: usize,
    redo: usize,
    /// Edits since the last save.
    unsaved: usize,
    /// Voxels (per material) and nodes per level of each root counted so far (roots are
    /// immutable).
    counts: FxHashMap<Root, RootCounts>,
    /// Voxels per material counted under each node (shared between roots).
    node_voxels: FxHashMap<(NodePtr, u32), MaterialCounts>,
    /// The hash DAG's GC count when the counts above were made (`GpuHashDag::collections`).
    counted_collections: u64,
}

/// Voxels and unique nodes per level under a root.
#[derive(Clone, Debug)]
struct RootCounts {
    voxels: u64,
    /// Voxels per material.
    materials: MaterialCounts,
    levels: Vec<u64>,
}

/// `svdag` with `materials` in new tables of `variant` sized by the load, every tool's
/// pipelines made now rather than in its first stroke (lavapipe: ~20 ms each), and the
/// collection's rather than in the first automatic GC.
fn editor_tables(
    ctx: &Arc<GpuContext>,
    svdag: &Svdag,
    materials: &Materials,
    undo_depth: usize,
    variant: HashVariant,
) -> Result<GpuHashDag> {
    let config = GpuHashDagConfig::sized_by_load(variant).with_undo_depth(undo_depth);
    let mut dag = GpuHashDag::load_materials(ctx, &config, svdag, materials, None)?;
    dag.prepare_tools(&brush::one_of_each())?;
    dag.prepare_gc()?;
    Ok(dag)
}

impl Document {
    /// Loads `svdag` with its `materials` (all 0 without) into a new hash DAG and binds it for
    /// `renderer` with the palette.
    fn load(
        ctx: &Arc<GpuContext>,
        renderer: &GpuRenderer,
        svdag: &Svdag,
        materials: Option<Materials>,
        path: PathBuf,
        undo_depth: usize,
        variant: HashVariant,
    ) -> Result<Document> {
        let file_palette = materials.as_ref().map_or(0, |m| m.palette.len());
        let materials = match materials {
            Some(m) => m,
            None => Materials::new(
                vec![pack_colour(DEFAULT_PALETTE[0])],
                vec![0; svdag.voxel_count() as usize],
            )?,
        };
        let mut palette = DEFAULT_PALETTE;
        for (entry, &c) in palette.iter_mut().zip(&materials.palette) {
            *entry = [c as u8, (c >> 8) as u8, (c >> 16) as u8];
        }
        let dag = editor_tables(ctx, svdag, &materials, undo_depth, variant)
            .with_context(|| format!("loading {} into the GPU hash DAG", path.display()))?;
        let scene = renderer.bind_hash_dag(&dag, Some(&palette))?;
        Ok(Document {
            scene,
            dag,
            binding: next_binding(),
            path,
            palette,
            file_palette,
            undo: 0,
            redo: 0,
            unsaved: 0,
            counts: FxHashMap::default(),
            node_voxels: FxHashMap::default(),
            counted_collections: 0,
        })
    }

    /// Binds the hash DAG again with the current palette (after an edit of a colour; the
    /// caller waits for frames in flight, which read the old binding).
    fn rebind(&mut self, renderer: &GpuRenderer) -> Result<()> {
        self.scene = renderer.bind_hash_dag(&self.dag, Some(&self.palette))?;
        self.binding = next_binding();
        Ok(())
    }

    /// Voxels and nodes per level of the current root (downloads the tables the first time a
    /// root is seen).
    fn counts(&mut self) -> Result<RootCounts> {
        self.counts_with(None)
    }

    /// [`Document::counts`], reading `image` (the tables downloaded already) where given.
    fn counts_with(&mut self, image: Option<&HashDagImage>) -> Result<RootCounts> {
        let root = self.dag.root();
        if self.counted_collections != self.dag.collections() {
            // A GC may have freed items the memos name and reused their handles.
            self.counts.clear();
            self.node_voxels.clear();
            self.counted_collections = self.dag.collections();
        }
        if let Some(c) = self.counts.get(&root) {
            return Ok(c.clone());
        }
        let downloaded;
        let image = match image {
            Some(image) => image,
            None => {
                downloaded = self.dag.download()?;
                &downloaded
            }
        };
        let materials = walk::voxels_per_material(image, root, &mut self.node_voxels)?;
        let counts = RootCounts {
            voxels: materials.iter().sum(),
            materials,
            levels: image.level_counts(root)?,
        };
        self.counts.insert(root, counts.clone());
        Ok(counts)
    }

    /// The current root as an svdag32 file at `path` (atomic write), with its materials and
    /// palette when the loaded file had them or an edit used a material other than 0.
    fn save(&mut self, path: &Path) -> Result<()> {
        let image = self.dag.download()?;
        let root = self.dag.root();
        let used = self
            .counts_with(Some(&image))?
            .materials
            .iter()
            .rposition(|&n| n > 0)
            .map_or(0, |m| m + 1);
        if self.file_palette == 0 && used <= 1 {
            image.to_svdag(root)?.save(path)?;
        } else {
            let entries = self.file_palette.max(used);
            let palette: Vec<u32> = self.palette[..entries]
                .iter()
                .map(|&c| pack_colour(c))
                .collect();
            image.to_file(root, Some(&palette))?.save(path)?;
        }
        self.unsaved = 0;
        Ok(())
    }
}

/// A new scene binding id (`Document::binding`).
fn next_binding() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// The RGBA8 word (opaque) of an sRGB colour.
fn pack_colour(c: [u8; 3]) -> u32 {
    c[0] as u32 | (c[1] as u32) << 8 | (c[2] as u32) << 16 | 0xff00_0000
}

/// Per frame-in-flight resources. `target` and `first_hits` follow the window size.
struct Slot {
    target: Option<Image>,
    /// One [`FirstHit`] per pixel of the frame (host-visible): the hit under the cursor.
    first_hits: Option<Buffer>,
    frame: RenderFrame,
    profiler: Profiler,
    /// The internal size and window size of the frame last recorded with this slot.
    view: Option<([u32; 2], [u32; 2])>,
    /// Input of the edit that frame is the first to show.
    edit_input: Option<EditInput>,
}

/// What an edit answered, for its latency.
#[derive(Clone, Copy, Debug)]
struct EditInput {
    /// When: the input event's delivery to the editor, else the start of the edit's frame.
    at: Instant,
    /// The earliest the event can have arrived: winit reads the window system's events between
    /// frames, so an event delivered after a frame may have arrived when that frame started
    /// (`at` for anything but an event).
    earliest: Instant,
    /// A press or pointer motion (not a held button's next frame, nor a replay line).
    event: bool,
}

impl EditInput {
    /// An edit of the frame that starts at `at` without new input (held button, replay).
    fn frame(at: Instant) -> EditInput {
        EditInput {
            at,
            earliest: at,
            event: false,
        }
    }
}

/// Frame and edit-latency statistics for `--stats-json` (the benchmark, docs/editor.md).
#[derive(Default)]
struct FrameStats {
    /// Frames presented, and when the first was.
    frames: usize,
    first: Option<Instant>,
    /// Frames presented between the first and the last edit (inclusive), and those times.
    edit_frames: usize,
    first_edit: Option<Instant>,
    last_edit: Option<Instant>,
    /// Input event to the end of the first frame showing the edit, per edit answering an
    /// event (a press or pointer motion), ms: from the event's delivery, and from the earliest
    /// moment it can have arrived.
    latencies: Vec<f64>,
    latency_bounds: Vec<f64>,
    /// The same for every edit, those of a held button without new input and replayed ones
    /// (from the start of their frame) included, ms.
    all_latencies: Vec<f64>,
    /// CPU wall time of each edit (ms).
    edit_ms: Vec<f64>,
    /// Render scale of each frame between the first and the last edit.
    scales: Vec<f32>,
}

/// Mean, median, 95th percentile and maximum of `v` (0 when empty).
fn summary(v: &[f64]) -> serde_json::Value {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let at = |q: f64| {
        s.get(((s.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(0.0)
    };
    let mean = s.iter().sum::<f64>() / s.len().max(1) as f64;
    serde_json::json!({
        "count": s.len(), "mean": mean, "p50": at(0.5), "p95": at(0.95), "max": at(1.0)
    })
}

/// The last edit: what the Profiler panel and the status file show.
#[derive(Clone, Debug, Serialize)]
struct LastEdit {
    /// Tool name.
    tool: String,
    /// Centre and radius.
    center: [f32; 3],
    radius: f32,
    /// CPU wall time of `GpuHashDag::edit` (ms).
    ms: f64,
    /// Input event to the end of presenting the first frame that shows it (ms).
    latency_ms: Option<f64>,
    /// GPU time per kernel (profiler passes); empty when the edit was not profiled.
    kernels: Vec<(String, f64)>,
}

/// What `--status-file` holds (rewritten atomically every frame).
#[derive(Serialize)]
struct Status<'a> {
    frame: usize,
    /// Fly speed factor (Shift + wheel).
    fly_speed: f32,
    voxels: Option<u64>,
    undo_depth: usize,
    redo_depth: usize,
    unsaved_edits: usize,
    tool: ToolKind,
    radius: f32,
    material: u8,
    /// Voxels per material of the current root.
    materials: Option<MaterialCounts>,
    palette: &'a Palette,
    copy: CopyState,
    hover: Option<[u32; 3]>,
    extent: [u32; 2],
    internal: [u32; 2],
    replay_done: bool,
    last_edit: Option<&'a LastEdit>,
    /// The last profiled edit (at most one a second while not tracing), with its kernels.
    profiled_edit: Option<&'a LastEdit>,
    message: Option<&'a str>,
    /// Scene and save paths, last file error, prompt, autosave, recording.
    #[serde(flatten)]
    files: files::FileStatus<'a>,
    /// Left-button presses on the scene (not taken by a panel) so far.
    clicks: usize,
    /// Presses a panel took.
    ui_clicks: usize,
    /// Key presses egui took (a focused widget): the shortcuts did not see them.
    ui_keys: usize,
    /// Hash table variant.
    table: &'a str,
    vsync: bool,
    present_mode: &'a str,
    /// Chrome traces written so far.
    traces_written: usize,
    /// Raster or path tracing.
    render_mode: RenderMode,
    /// Path tracing: samples per pixel accumulated (0 in raster mode).
    samples: u32,
    /// Path tracing: bounces and samples added per frame.
    bounces: u32,
    spp: u32,
}

/// The open editor. The window (presenter: waits for the GPU) drops first.
struct Running {
    win: GpuWindow,
    slots: Vec<Slot>,
    doc: Document,
    renderer: GpuRenderer,
    edit_profiler: Profiler,
    ctx: Arc<GpuContext>,
    input: CameraInput,
    modifiers: ModifiersState,
    tool: ToolKind,
    radius: f32,
    material: u8,
    /// The copy tool's source and rotation.
    copy: CopyState,
    /// A palette colour changed in this frame's panels: bind the scene again.
    palette_changed: bool,
    /// Left button held over the scene: one edit per frame.
    painting: bool,
    /// A press not yet turned into an edit, with its time (so a click shorter than a frame
    /// still edits).
    click: Option<EditInput>,
    /// The voxel under the cursor and its entry normal (last completed frame).
    hover: Option<FirstHit>,
    user_scale: f32,
    dynamic_scale: bool,
    ms_per_pixel: Option<f64>,
    internal: [u32; 2],
    scale: f32,
    last_passes: Vec<PassTiming>,
    last_edit: Option<LastEdit>,
    /// When the last profiled edit ended, and the edit with its kernels: the Profiler panel's
    /// breakdown.
    profiled_edit: Option<(Instant, LastEdit)>,
    /// Input of an edit not yet shown in a presented frame.
    edit_input: Option<EditInput>,
    last_frame: Option<Instant>,
    frame_ms: f64,
    /// Wall time of an editing frame outside its render (edit, panels, present; moving
    /// average): the dynamic scale leaves it out of the editing frame's budget.
    frame_rest_ms: Option<f64>,
    frames: usize,
    steps: record::Playlist,
    replay_done: bool,
    /// The replay is done and --exit-after-replay was given: screenshot, save, exit.
    wrap_up: bool,
    /// Raster or path tracing (Settings panel, P).
    render_mode: RenderMode,
    /// The path tracer, made when first used.
    pt: Option<PtState>,
    /// Path tracing: bounces, samples per frame, samples at which accumulation stops, light.
    bounces: u32,
    spp: u32,
    max_samples: u32,
    lighting: PtLighting,
    /// The last error or notice (shown in the Scene panel and the status file).
    message: Option<String>,
    save_path: String,
    /// File panel, prompts, autosave and recording (tools/editor/files.rs).
    files: files::FileState,
    exit: bool,
    /// Left-button presses on the scene and on the panels.
    clicks: usize,
    ui_clicks: usize,
    /// Key presses egui took.
    ui_keys: usize,
    /// Settings and Profiler panel state (`panels`).
    ui: PanelState,
    /// Chrome traces written so far.
    traces_written: usize,
    /// `--stats-json` statistics.
    stats: FrameStats,
    /// The last pointer motion (the input of an edit while the button is held).
    last_pointer: Option<EditInput>,
    /// When the last frame started (the bound on an event's arrival, [`EditInput::earliest`]).
    redraw_start: Option<Instant>,
}

impl Running {
    /// Input: egui first, then shortcuts, tools and the camera.
    fn handle(&mut self, event: &WindowEvent) {
        let consumed = self
            .win
            .egui_state
            .on_window_event(&self.win.window, event)
            .consumed;
        match event {
            WindowEvent::CloseRequested => self.request_close(),
            WindowEvent::Resized(size) => self.win.presenter.resize([size.width, size.height]),
            WindowEvent::ModifiersChanged(m) => {
                self.modifiers = m.state();
                self.input.fast = self.modifiers.shift_key();
            }
            WindowEvent::Focused(false) => {
                self.input.keys.clear();
                self.painting = false;
            }
            WindowEvent::MouseInput {
                state: ElementState::Released,
                button,
                ..
            } => match button {
                MouseButton::Left => {
                    self.painting = false;
                    self.input.orbit_drag = false;
                }
                MouseButton::Middle => self.input.orbit_drag = false,
                MouseButton::Right => self.input.look_drag = false,
                _ => {}
            },
            WindowEvent::CursorMoved { position, .. } => {
                self.last_pointer = Some(self.event_input());
                self.input.cursor_moved(*position)
            }
            WindowEvent::MouseInput {
                button: MouseButton::Left,
                ..
            } if consumed => self.ui_clicks += 1,
            WindowEvent::KeyboardInput { event, .. }
                if consumed && event.state == ElementState::Pressed =>
            {
                self.ui_keys += 1
            }
            _ if consumed => {}
            WindowEvent::KeyboardInput { event, .. } => {
                let PhysicalKey::Code(code) = event.physical_key else {
                    return;
                };
                if event.state != ElementState::Pressed {
                    self.input.keys.remove(&code);
                    return;
                }
                let ctrl = self.modifiers.control_key();
                let shift = self.modifiers.shift_key();
                if self.file_key(code, ctrl, shift) {
                    return;
                }
                match code {
                    KeyCode::Home => self.input.go_home(),
                    KeyCode::KeyZ if ctrl && shift => self.redo(),
                    KeyCode::KeyZ | KeyCode::KeyY if ctrl => {
                        if code == KeyCode::KeyZ {
                            self.undo()
                        } else {
                            self.redo()
                        }
                    }
                    KeyCode::KeyT if !ctrl => {
                        self.ui.pending_variant =
                            Some(panels::next_variant(self.doc.dag.config().variant));
                    }
                    KeyCode::KeyP if !ctrl => {
                        self.render_mode = match self.render_mode {
                            RenderMode::Raster => RenderMode::Pt,
                            RenderMode::Pt => RenderMode::Raster,
                        };
                    }
                    KeyCode::KeyR if !ctrl => {
                        self.copy.quarter_turns = (self.copy.quarter_turns + 1) % 4;
                    }
                    _ if tool_key(code).is_some() => {
                        self.tool = ToolKind::ALL[tool_key(code).expect("checked")];
                    }
                    _ if !ctrl => {
                        self.input.keys.insert(code);
                    }
                    _ => {}
                }
            }
            WindowEvent::MouseInput {
                state: ElementState::Pressed,
                button,
                ..
            } => match button {
                MouseButton::Left if self.modifiers.alt_key() => self.input.orbit_drag = true,
                MouseButton::Left if self.tool == ToolKind::Copy && self.modifiers.shift_key() => {
                    self.clicks += 1;
                    self.copy.source = self.brush_center();
                }
                MouseButton::Left => {
                    self.clicks += 1;
                    self.painting = true;
                    self.click = Some(self.event_input());
                }
                MouseButton::Middle => self.input.orbit_drag = true,
                MouseButton::Right => self.input.look_drag = true,
                _ => {}
            },
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => *y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                if self.modifiers.control_key() {
                    self.radius = (self.radius * 1.1f32.powf(lines)).clamp(1.0, MAX_RADIUS);
                } else if self.modifiers.shift_key() {
                    self.input.scale_fly_speed(lines);
                } else {
                    self.input.zoom(lines);
                }
            }
            _ => {}
        }
    }

    /// Undoes the last edit (if any).
    fn undo(&mut self) {
        if self.doc.dag.undo() {
            self.doc.undo -= 1;
            self.doc.redo += 1;
            self.doc.unsaved += 1;
            self.record(Action::Undo);
        }
    }

    /// Redoes the last undone edit (if any).
    fn redo(&mut self) {
        if self.doc.dag.redo() {
            self.doc.undo += 1;
            self.doc.redo -= 1;
            self.doc.unsaved += 1;
            self.record(Action::Redo);
        }
    }

    /// Applies `tool`; the result becomes the current root. Errors (pool full, bad tool) are
    /// shown and leave the scene as it was.
    fn apply(&mut self, tool: &Tool, input: EditInput) -> Result<()> {
        let Some(tool) = self.recordable(tool) else {
            return Ok(());
        };
        let tool = &tool;
        // GC (automatic, inside `edit`) may free nodes of roots that left the history while
        // frames in flight still read them.
        self.ctx.wait_idle()?;
        // The wait finished the frames in flight: the last edit's first frame among them.
        self.observe_shown_edits()?;
        // While a trace records, the edit's kernels go into it too. Otherwise at most one edit a
        // second is profiled: on lavapipe the timestamps around its ~100 passes cost about as
        // much as the edit itself.
        let tracing = self.ui.trace.is_some();
        let profile = tracing
            || self
                .profiled_edit
                .as_ref()
                .is_none_or(|(t, _)| t.elapsed() >= EDIT_PROFILE_INTERVAL);
        let (profiler, before) = match &mut self.ui.trace {
            Some(t) => {
                let n = t.profiler.passes().len();
                (&mut t.profiler, n)
            }
            None => {
                self.edit_profiler.clear();
                (&mut self.edit_profiler, 0)
            }
        };
        let start = Instant::now();
        let result = self.doc.dag.edit(tool, profile.then_some(&mut *profiler));
        let end = Instant::now();
        let ms = (end - start).as_secs_f64() * 1e3;
        if let Err(e) = result {
            self.message = Some(format!("edit failed: {e}"));
            return Ok(());
        }
        if tracing {
            profiler.record_cpu_span("edit", start, end);
        }
        self.stats.edit_ms.push(ms);
        self.stats.first_edit.get_or_insert(end);
        self.stats.last_edit = Some(end);
        // The edit resolved its passes; sum them per kernel (one pass per level).
        let mut kernels: Vec<(String, f64)> = Vec::new();
        for p in &profiler.passes()[before..] {
            match kernels.iter_mut().find(|k| k.0 == p.name) {
                Some(k) => k.1 += p.gpu_ms,
                None => kernels.push((p.name.clone(), p.gpu_ms)),
            }
        }
        self.doc.undo = (self.doc.undo + 1).min(self.doc.dag.undo_depth());
        self.doc.redo = 0;
        self.doc.unsaved += 1;
        self.record(record::action_of(tool));
        let (name, center, radius) = match *tool {
            Tool::Add { center, radius, .. } => ("add", center, radius),
            Tool::Remove { center, radius, .. } => ("remove", center, radius),
            Tool::Paint { center, radius, .. } => ("paint", center, radius),
            Tool::Fill { center, radius, .. } => ("fill", center, radius),
            Tool::Copy(c) => ("copy", c.dest, c.radius),
        };
        let edit = LastEdit {
            tool: name.into(),
            center,
            radius,
            ms,
            latency_ms: None,
            kernels,
        };
        if profile {
            self.profiled_edit = Some((end, edit.clone()));
        }
        self.last_edit = Some(edit);
        self.edit_input = Some(input);
        Ok(())
    }
}

impl Running {
    /// An input event delivered now.
    fn event_input(&self) -> EditInput {
        let at = Instant::now();
        EditInput {
            at,
            earliest: self.redraw_start.map_or(at, |s| s.min(at)),
            event: true,
        }
    }

    /// Records the latency of every edit whose first frame the GPU has finished: that frame's
    /// image is complete and handed to the presentation engine. Polled (it never waits) at the
    /// start of a frame and right after an edit's wait for the frames in flight, so the time is
    /// the first moment the CPU sees it: an upper bound of the true latency.
    fn observe_shown_edits(&mut self) -> Result<()> {
        for index in 0..self.slots.len() {
            if self.slots[index].edit_input.is_none() || !self.win.presenter.slot_finished(index)? {
                continue;
            }
            let input = self.slots[index].edit_input.take().expect("checked above");
            let latency = input.at.elapsed().as_secs_f64() * 1e3;
            self.stats.all_latencies.push(latency);
            if input.event {
                self.stats.latencies.push(latency);
                let bound = input.earliest.elapsed().as_secs_f64() * 1e3;
                self.stats.latency_bounds.push(bound);
            }
            if let Some(edit) = &mut self.last_edit {
                edit.latency_ms = Some(latency);
            }
        }
        Ok(())
    }

    /// The render scale of this frame: the user's, or lower while the camera moves or the
    /// button edits. Moving, the render aims at [`MOTION_TARGET_MS`]; editing, the whole frame
    /// aims at [`EDIT_FRAME_TARGET_MS`]: the render gets what the edit and the rest of the
    /// frame (measured, [`Running::frame_rest_ms`]) leave, at least [`EDIT_RENDER_MIN_MS`].
    fn frame_scale(&self, extent: [u32; 2]) -> f32 {
        if !self.dynamic_scale || !(self.input.moving() || self.painting) {
            return self.user_scale;
        }
        let Some(ms_per_pixel) = self.ms_per_pixel else {
            return self.user_scale;
        };
        let target = match (self.painting, self.frame_rest_ms) {
            (true, Some(rest)) => {
                (EDIT_FRAME_TARGET_MS - rest).clamp(EDIT_RENDER_MIN_MS, MOTION_TARGET_MS)
            }
            _ => MOTION_TARGET_MS,
        };
        let full = ms_per_pixel * extent[0] as f64 * extent[1] as f64;
        let scale = (target / full.max(1e-9)).sqrt() as f32;
        scale.clamp(MIN_SCALE, self.user_scale)
    }

    /// Updates [`Running::frame_rest_ms`] with a frame of `frame_ms` whose render at `internal`
    /// is estimated from the measured cost per pixel; only frames that edited count.
    fn measure_frame_rest(&mut self, frame_ms: f64, internal: [u32; 2], edited: bool) {
        if !edited {
            return;
        }
        let Some(ms_per_pixel) = self.ms_per_pixel else {
            return;
        };
        let render = ms_per_pixel * internal[0] as f64 * internal[1] as f64;
        let rest = (frame_ms - render).max(0.0);
        self.frame_rest_ms = Some(self.frame_rest_ms.map_or(rest, |o| 0.8 * o + 0.2 * rest));
    }

    /// Path tracing: makes the tracer on first use and prepares this frame's accumulation,
    /// returning the samples to record; `None` in raster mode (and when the tracer cannot be
    /// made: the error is shown and the mode goes back to raster).
    fn pt_prepare(&mut self, internal: [u32; 2]) -> Result<Option<Range<u32>>> {
        if self.render_mode != RenderMode::Pt {
            return Ok(None);
        }
        if self.pt.is_none() {
            match PtState::new(&self.ctx) {
                Ok(p) => self.pt = Some(p),
                Err(e) => {
                    self.message = Some(format!("path tracing unavailable: {e:#}"));
                    self.render_mode = RenderMode::Raster;
                    return Ok(None);
                }
            }
        }
        let key = PtKey {
            camera: self.input.camera,
            internal,
            binding: self.doc.binding,
            root: self.doc.dag.root(),
            bounces: self.bounces,
            lighting: self.lighting,
        };
        let pt = self.pt.as_mut().expect("made above");
        let samples = pt.prepare(&self.ctx, &self.doc.scene, key, self.spp, self.max_samples)?;
        Ok(Some(samples))
    }

    /// Samples per pixel accumulated (0 in raster mode).
    fn pt_samples(&self) -> u32 {
        match (self.render_mode, &self.pt) {
            (RenderMode::Pt, Some(p)) => p.samples,
            _ => 0,
        }
    }

    /// The voxel under the cursor in the slot's last frame (its fence has signalled).
    fn read_hover(&self, slot: &Slot) -> Result<Option<FirstHit>> {
        let (Some(cursor), Some((internal, extent)), Some(hits)) =
            (self.input.cursor, slot.view, &slot.first_hits)
        else {
            return Ok(None);
        };
        let x = (cursor.x / extent[0] as f64 * internal[0] as f64).floor();
        let y = (cursor.y / extent[1] as f64 * internal[1] as f64).floor();
        if x < 0.0 || y < 0.0 || x >= internal[0] as f64 || y >= internal[1] as f64 {
            return Ok(None);
        }
        let index = y as u64 * internal[0] as u64 + x as u64;
        let size = std::mem::size_of::<FirstHit>() as u64;
        let hit: Vec<FirstHit> = self.ctx.read_buffer(hits, index * size, 1)?;
        Ok(hit.into_iter().next().filter(|h| h.hit == 1))
    }

    /// The tool centre for the hovered voxel: the empty voxel in front of it when adding, the
    /// voxel itself otherwise.
    fn brush_center(&self) -> Option<[f32; 3]> {
        let hit = self.hover?;
        let offset = if self.tool.in_front() { 1 } else { 0 };
        Some([0, 1, 2].map(|a| (hit.voxel[a] as i64 + offset * hit.normal[a] as i64) as f32 + 0.5))
    }

    /// One frame: hover hit, edits, panels, render, present, status file.
    fn redraw(&mut self, args: &EditorArgs) -> Result<()> {
        self.redraw_start = Some(Instant::now());
        let dt = self
            .last_frame
            .map_or(0.0, |t| t.elapsed().as_secs_f32().min(0.1));
        let Some(frame) = self.win.presenter.begin_frame()? else {
            return Ok(());
        };
        // The slot's last frame has finished (and maybe others): their edits are shown.
        self.observe_shown_edits()?;
        let frame_start = Instant::now();
        let passes = {
            let slot = &mut self.slots[frame.index];
            let passes = slot.profiler.resolve()?;
            slot.profiler.clear();
            passes
        };
        // The render passes of either mode: primary rays, or the path tracer's samples (a
        // frame past --max-samples only displays: it says nothing of a moving frame's cost).
        let render_ms: Vec<f64> = passes
            .iter()
            .filter(|p| {
                p.name == "primary rays" || (p.name.starts_with("pt ") && p.name != "pt display")
            })
            .map(|p| p.gpu_ms)
            .collect();
        if !render_ms.is_empty() {
            let pixels = (self.internal[0] as f64 * self.internal[1] as f64).max(1.0);
            let sample = render_ms.iter().sum::<f64>() / pixels;
            self.ms_per_pixel = Some(self.ms_per_pixel.map_or(sample, |o| 0.8 * o + 0.2 * sample));
        }
        if !passes.is_empty() {
            self.last_passes = passes;
        }
        self.hover = self.read_hover(&self.slots[frame.index])?;

        // Edits: the replay's, else the tool under the cursor (a click, then every frame while
        // the button is held).
        let finishing = !self.replay_done;
        if !self.replay_done {
            self.replay_frame(args.files.replay_pace)?;
        } else if self.click.is_some() || self.painting {
            // A press, else (button held) the last pointer motion not yet edited for, else now.
            let since = self.stats.last_edit;
            let moved = self.last_pointer.filter(|p| since.is_none_or(|e| p.at > e));
            let input = self
                .click
                .take()
                .or(moved)
                .unwrap_or(EditInput::frame(frame_start));
            if let Some(center) = self.brush_center() {
                match brush::tool(self.tool, center, self.radius, self.material, &self.copy) {
                    Some(tool) => self.apply(&tool, input)?,
                    None => {
                        self.message = Some("copy: Shift+click picks the source first".into());
                    }
                }
            }
        }
        if finishing && self.replay_done && args.exit_after_replay {
            self.wrap_up = true;
        }
        // The screenshot is taken at scale 1 (path tracing: once --max-samples are in).
        let shooting = self.wrap_up && args.screenshot.is_some();
        self.files_frame();
        self.doc
            .scene
            .set_hash_root(&self.doc.dag, self.doc.dag.root())?;
        // Counting downloads the tables once per new root: only for the status file and not
        // while the button is held (one new root per frame); the Scene panel counts when open.
        let counts = if args.status_file.is_some() && !self.painting {
            self.counts_or_message()
        } else {
            None
        };

        let extent = frame.extent;
        self.input.fly(dt);
        let scale = if shooting {
            1.0
        } else {
            self.frame_scale(extent)
        };
        let internal = [
            ((extent[0] as f32 * scale).round() as u32).clamp(1, extent[0]),
            ((extent[1] as f32 * scale).round() as u32).clamp(1, extent[1]),
        ];
        self.scale = scale;
        self.internal = internal;
        let mut settings = RenderSettings::new(internal[0], internal[1], self.input.camera);
        // The brush preview, drawn by the renderer; never in replayed or screenshot frames.
        let preview = self
            .brush_center()
            .filter(|_| self.replay_done && !self.wrap_up)
            .map(|c| {
                let material = self.doc.palette[self.material as usize];
                brush::preview(self.tool, c, self.radius, material)
            });

        let raw_input = self.win.egui_state.take_egui_input(&self.win.window);
        let egui = self.win.egui.clone();
        let output = egui.run_ui(raw_input, |ui| self.panels(ui, extent));
        self.win
            .egui_state
            .handle_platform_output(&self.win.window, output.platform_output);
        let primitives = egui.tessellate(output.shapes, output.pixels_per_point);
        if std::mem::take(&mut self.palette_changed) {
            // Frames in flight read the old palette buffer.
            self.ctx.wait_idle()?;
            self.doc.rebind(&self.renderer)?;
        }
        self.apply_settings()?;
        let samples = self.pt_prepare(internal)?;
        let screenshot = shooting
            && samples.as_ref().is_none_or(|_| {
                self.pt
                    .as_ref()
                    .is_some_and(|p| p.samples >= self.max_samples)
            });
        settings.preview = preview.filter(|_| samples.is_none());

        let slot = &mut self.slots[frame.index];
        if slot
            .target
            .as_ref()
            .is_none_or(|t| t.width() != extent[0] || t.height() != extent[1])
        {
            // Resized: the slot's old images belong to a finished frame.
            slot.target = Some(self.ctx.create_storage_image(
                &format!("editor target {}", frame.index),
                extent[0],
                extent[1],
            )?);
            let bytes =
                extent[0] as u64 * extent[1] as u64 * std::mem::size_of::<FirstHit>() as u64;
            slot.first_hits = Some(self.ctx.create_buffer(
                &format!("editor first hits {}", frame.index),
                bytes,
                MemLocation::GpuToCpu,
            )?);
        }
        let target = slot.target.as_ref().expect("allocated above");
        let hits = slot.first_hits.as_ref().expect("allocated above");
        // A trace being recorded takes the frame's passes (resolved when it is written).
        let profiler = match &mut self.ui.trace {
            Some(t) => &mut t.profiler,
            None => &mut slot.profiler,
        };
        let mut cmd = self.ctx.begin_commands("editor frame")?;
        match (samples, &self.pt) {
            (Some(samples), Some(pt)) => pt.record(
                &mut cmd,
                &self.doc.scene,
                samples,
                target,
                hits,
                preview.as_ref(),
                Some(&mut *profiler),
            )?,
            _ => self.renderer.record_with_first_hits(
                &mut cmd,
                &self.doc.scene,
                &mut slot.frame,
                &settings,
                target,
                hits,
                Some(&mut *profiler),
            )?,
        }
        slot.view = Some((internal, extent));
        slot.edit_input = self.edit_input.take();
        let edited = slot.edit_input.is_some();
        self.win.presenter.end_frame(
            cmd,
            target,
            internal,
            Some(OverlayFrame {
                primitives: &primitives,
                textures_delta: output.textures_delta,
                pixels_per_point: output.pixels_per_point,
            }),
            screenshot,
            Some(&mut *profiler),
        )?;
        self.frames += 1;
        let now = Instant::now();
        if let Some(t) = &mut self.ui.trace {
            t.profiler.record_cpu_span("frame", frame_start, now);
        }
        self.trace_frame_done()?;
        if let Some(prev) = self.last_frame {
            self.frame_ms = (now - prev).as_secs_f64() * 1e3;
            self.ui.push_frame_time(self.frame_ms as f32);
            self.measure_frame_rest(self.frame_ms, internal, edited);
        }
        self.last_frame = Some(now);
        self.count_frame(now);

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
        if let Some(path) = &args.status_file {
            let status = Status {
                frame: self.frames,
                fly_speed: self.input.fly_speed,
                voxels: counts.as_ref().map(|c| c.voxels),
                undo_depth: self.doc.undo,
                redo_depth: self.doc.redo,
                unsaved_edits: self.doc.unsaved,
                tool: self.tool,
                radius: self.radius,
                material: self.material,
                materials: counts.as_ref().map(|c| c.materials),
                palette: &self.doc.palette,
                copy: self.copy,
                hover: self.hover.map(|h| h.voxel),
                extent,
                internal,
                replay_done: self.replay_done,
                last_edit: self.last_edit.as_ref(),
                profiled_edit: self.profiled_edit.as_ref().map(|(_, e)| e),
                message: self.message.as_deref(),
                clicks: self.clicks,
                ui_clicks: self.ui_clicks,
                ui_keys: self.ui_keys,
                files: self.file_status(),
                table: self.doc.dag.config().variant.name(),
                vsync: self.ui.vsync,
                present_mode: &self.win.presenter.stats().present_mode,
                traces_written: self.traces_written,
                render_mode: self.render_mode,
                samples: self.pt_samples(),
                bounces: self.bounces,
                spp: self.spp,
            };
            write_json(path, &status)?;
        }
        self.record_frame();
        if self.wrap_up && (args.screenshot.is_none() || screenshot) {
            if let Some(path) = &args.save {
                self.doc.save(path)?;
                println!("{}: saved after the replay", path.display());
            }
            self.exit = true;
        }
        Ok(())
    }

    /// The egui panels: Tools, Scene, Profiler, Settings, and the copy tool's source outline.
    fn panels(&mut self, ui: &mut egui::Ui, extent: [u32; 2]) {
        let ctx = ui.ctx().clone();
        if let (ToolKind::Copy, Some(source)) = (self.tool, self.copy.source) {
            brush::draw_copy_source(&ctx, &self.input.camera, extent, source, self.radius);
        }
        self.files_panel(&ctx);
        egui::Window::new("Tools")
            .default_pos([8.0, 8.0])
            .resizable(false)
            .show(&ctx, |ui| {
                self.tools_panel(ui);
                ui.horizontal(|ui| {
                    if ui
                        .add_enabled(self.doc.undo > 0, egui::Button::new("undo"))
                        .clicked()
                    {
                        self.undo();
                    }
                    if ui
                        .add_enabled(self.doc.redo > 0, egui::Button::new("redo"))
                        .clicked()
                    {
                        self.redo();
                    }
                    if ui.button("GC").clicked() {
                        self.message = Some(match self.collect() {
                            Ok(text) => text,
                            Err(e) => format!("GC failed: {e:#}"),
                        });
                    }
                });
                if self.render_mode == RenderMode::Pt {
                    ui.label(format!(
                        "path tracing: {} / {} samples (P: raster)",
                        self.pt_samples(),
                        self.max_samples
                    ));
                }
            });
        egui::Window::new("Scene")
            .default_pos([8.0, 330.0])
            .default_open(false)
            .show(&ctx, |ui| self.scene_panel(ui));
        egui::Window::new("Profiler")
            .default_pos([(extent[0] as f32 - 260.0).max(8.0), 8.0])
            .default_open(false)
            .show(&ctx, |ui| self.profiler_panel(ui));
        egui::Window::new("Settings")
            .default_pos([(extent[0] as f32 - 260.0).max(8.0), 300.0])
            .default_open(false)
            .show(&ctx, |ui| self.settings_panel(ui, extent));
    }

    /// Scene: file, resolution, voxels and nodes per level, history, table bytes, save / open.
    fn scene_panel(&mut self, ui: &mut egui::Ui) {
        let counts = self.counts_or_message();
        let dag = &self.doc.dag;
        ui.label(format!("file {}", self.doc.path.display()));
        ui.label(format!("resolution {}^3", dag.resolution()));
        if let Some(c) = &counts {
            ui.label(format!("voxels {}", c.voxels));
            ui.label("nodes per level (0 = leaves)");
            for (level, n) in c.levels.iter().enumerate() {
                ui.label(format!("  {level}: {n}"));
            }
        }
        ui.label(format!(
            "history: {} undo, {} redo (depth {}), {} unsaved edits",
            self.doc.undo,
            self.doc.redo,
            dag.undo_depth(),
            self.doc.unsaved
        ));
        ui.label(format!("tables {} bytes on the GPU", dag.gpu_bytes()));
        for words in 2..=10 {
            if let Some(t) = dag.table(words) {
                ui.label(format!("  {words}-word items: {} bytes", t.gpu_bytes()));
            }
        }
        ui.label("open, save, import, export, record: the File panel");
        if let Some(m) = &self.message {
            ui.colored_label(egui::Color32::YELLOW, m);
        }
    }

    /// The current root's counts; an error becomes the message.
    fn counts_or_message(&mut self) -> Option<RootCounts> {
        match self.doc.counts() {
            Ok(c) => Some(c),
            Err(e) => {
                self.message = Some(format!("counting voxels: {e:#}"));
                None
            }
        }
    }

    /// Counts a presented frame for `--stats-json`.
    fn count_frame(&mut self, now: Instant) {
        let stats = &mut self.stats;
        stats.frames += 1;
        stats.first.get_or_insert(now);
        if stats.first_edit.is_some() && self.painting {
            stats.edit_frames += 1;
            stats.scales.push(self.scale);
        }
    }

    /// The `--stats-json` document: frames, fps while editing, edit latency and time.
    fn stats_json(&self, args: &EditorArgs) -> serde_json::Value {
        let s = &self.stats;
        let seconds = |a: Option<Instant>, b: Option<Instant>| match (a, b) {
            (Some(a), Some(b)) => (b - a).as_secs_f64(),
            _ => 0.0,
        };
        let editing = seconds(s.first_edit, s.last_edit);
        let scales: Vec<f64> = s.scales.iter().map(|&x| x as f64).collect();
        serde_json::json!({
            "scene": args.scene,
            "resolution": self.doc.dag.resolution(),
            "window": self.win.presenter.extent(),
            "table": self.doc.dag.config().variant.name(),
            "present_mode": self.win.presenter.stats().present_mode,
            "tool": self.tool,
            "radius": self.radius,
            "frames": s.frames,
            "seconds": seconds(s.first, self.last_frame),
            "edits": s.edit_ms.len(),
            "editing_seconds": editing,
            "editing_frames": s.edit_frames,
            "editing_fps": if editing > 0.0 { s.edit_frames as f64 / editing } else { 0.0 },
            "editing_render_scale": summary(&scales),
            "edit_latency_ms": summary(&s.latencies),
            "edit_latency_bound_ms": summary(&s.latency_bounds),
            "edit_latency_all_ms": summary(&s.all_latencies),
            "edit_ms": summary(&s.edit_ms),
        })
    }

    /// Runs the GPU GC over every live root.
    fn collect(&mut self) -> Result<String> {
        self.ctx.wait_idle()?;
        let stats = self.doc.dag.gc(None)?;
        Ok(format!(
            "GC freed {} items ({} kept) in {:.1} ms",
            stats.freed, stats.live, stats.ms
        ))
    }

    /// The tools, the radius slider, the copy source and rotation, the palette (16 swatches,
    /// the selected one's colour editable).
    fn tools_panel(&mut self, ui: &mut egui::Ui) {
        for (i, kind) in ToolKind::ALL.iter().enumerate() {
            ui.radio_value(
                &mut self.tool,
                *kind,
                format!("{} ({})", kind.label(), i + 1),
            );
        }
        ui.add(
            egui::Slider::new(&mut self.radius, 1.0..=MAX_RADIUS)
                .logarithmic(true)
                .text("radius (Ctrl+wheel)"),
        );
        if self.tool == ToolKind::Copy {
            ui.horizontal(|ui| {
                match self.copy.source {
                    Some(s) => ui.label(format!("source {:.0?}", s)),
                    None => ui.label("no source: Shift+click"),
                };
                if ui.button("clear").clicked() {
                    self.copy.source = None;
                }
            });
            ui.horizontal(|ui| {
                ui.label("rotation (R)");
                for turns in 0..4u8 {
                    ui.radio_value(
                        &mut self.copy.quarter_turns,
                        turns,
                        format!("{}", 90 * turns as u32),
                    );
                }
            });
        }
        ui.label("material (add, paint, fill)");
        egui::Grid::new("palette").show(ui, |ui| {
            for (m, colour) in self.doc.palette.iter().enumerate() {
                let selected = self.material as usize == m;
                let [r, g, b] = *colour;
                let button = egui::Button::new("  ")
                    .fill(egui::Color32::from_rgb(r, g, b))
                    .stroke(if selected {
                        egui::Stroke::new(2.0, egui::Color32::WHITE)
                    } else {
                        egui::Stroke::NONE
                    });
                if ui.add(button).clicked() {
                    self.material = m as u8;
                }
                if m % 8 == 7 {
                    ui.end_row();
                }
            }
        });
        let m = self.material as usize;
        let before = self.doc.palette[m];
        ui.horizontal(|ui| {
            ui.label(format!("material {m}"));
            ui.color_edit_button_srgb(&mut self.doc.palette[m]);
        });
        if self.doc.palette[m] != before {
            self.palette_changed = true;
        }
    }
}
