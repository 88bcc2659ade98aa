//! File handling of `voxdag editor`: open, save and save as, import of a mesh / `.vox`, export
//! to `.vox` / xyz-u32, autosave to a side file with recovery on start, the prompt for unsaved
//! changes on close, and the File panel. A child module of the editor: it reaches the editor's
//! private state. See docs/editor.md ("Files").

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Result};
use clap::{Args, ValueEnum};
use serde::Serialize;
use voxdag::attr::Materials;
use voxdag::dag::{export_vox, export_xyz_u32_file, Svdag, VdagFile};
use voxdag::edit::item::Root;
use voxdag::render::Camera;
use winit::keyboard::KeyCode;

use super::record::{Pace, Recorder};
use super::{load_scene, scene_size, Document, Running};
use crate::window::CameraInput;

/// The egui id of the File panel (its collapsing state is unfolded by the shortcuts).
const FILE_PANEL: &str = "voxdag editor file panel";

/// The file options of `voxdag editor`.
#[derive(Args)]
pub struct FileArgs {
    /// Write the scene to SCENE.autosave (atomically) this often while it has unsaved edits;
    /// 0: never (the close prompt still writes it).
    #[arg(long, default_value_t = 120)]
    pub autosave_secs: u64,
    /// When SCENE.autosave is newer than SCENE at start: ask (a prompt), yes (load it), no.
    #[arg(long, value_enum, default_value_t = Recover::Ask)]
    pub recover: Recover,
    /// Record the session to this HashDAG replay CSV (camera, edits, undo / redo, EndFrame).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Pace of --replay: recorded (one frame per EndFrame line) or fast.
    #[arg(long, value_enum, default_value_t = Pace::Recorded)]
    pub replay_pace: Pace,
}

/// What to do with a newer autosave at start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Recover {
    /// Show a prompt.
    Ask,
    /// Load it.
    Yes,
    /// Keep the scene.
    No,
}

/// The File panel's path fields (Ctrl+O, Ctrl+Shift+S, Ctrl+I, Ctrl+E, Ctrl+R focus them;
/// Enter runs them).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
enum Field {
    Open,
    SaveAs,
    Import,
    Export,
    Record,
}

/// A prompt waiting for an answer (shown over everything; keys answer it too).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Prompt {
    /// The autosave is newer than the scene: recover it (Y / Enter) or not (N / Esc)?
    Recover,
    /// Closing with unsaved edits: Save (S), Discard (D) or Cancel (C / Esc)?
    Unsaved,
}

/// A file action run at the start of the next frame (not inside the panels' closure).
enum Pending {
    Open(PathBuf),
    SaveAs(PathBuf),
    Import(PathBuf, u32),
    Export(PathBuf),
    Record(PathBuf),
    Recover,
    CloseSave,
    CloseDiscard,
}

/// File state of the open editor.
pub struct FileState {
    open: String,
    save_as: String,
    import: String,
    /// Grid side for imports (0: a .vox's own size).
    import_resolution: u32,
    export: String,
    record: String,
    /// A field to focus on the next frame.
    focus: Option<Field>,
    /// The field with the keyboard focus in the last frame.
    focused: Option<Field>,
    pending: Option<Pending>,
    prompt: Option<Prompt>,
    /// The last failed file action (shown in red, in the status file).
    last_error: Option<String>,
    /// Autosave interval in seconds (0: off); `--autosave-secs`, a setting in the panel.
    autosave_secs: u64,
    last_autosave: Instant,
    /// The root last written to the autosave.
    autosaved_root: Option<Root>,
    autosaves: usize,
    /// The session recording, if any.
    pub recorder: Option<Recorder>,
}

/// The file fields of the status file.
#[derive(Serialize)]
pub struct FileStatus<'a> {
    scene_path: String,
    save_path: &'a str,
    last_error: Option<&'a str>,
    prompt: Option<Prompt>,
    /// The File panel field being typed in.
    focused_field: Option<Field>,
    autosave_path: String,
    /// Autosaves written so far.
    autosaves: usize,
    recording: Option<String>,
    recorded_lines: usize,
}

/// The side file the scene at `scene` autosaves to.
pub fn autosave_path(scene: &Path) -> PathBuf {
    let mut name = scene.as_os_str().to_owned();
    name.push(".autosave");
    PathBuf::from(name)
}

/// Whether `a` was modified after `b` (false when either cannot be read).
fn newer(a: &Path, b: &Path) -> bool {
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    match (modified(a), modified(b)) {
        (Some(a), Some(b)) => a > b,
        _ => false,
    }
}

/// The DAG and materials of an autosave file (what `load_scene` reads from a `.vdag`).
fn load_autosave(path: &Path) -> Result<(Svdag, Option<Materials>)> {
    let mut file = VdagFile::load_encoded_colors(path)?;
    let materials = file.materials.take();
    let mut dag = file.into_svdag(path)?;
    dag.colors.clear();
    Ok((dag, materials))
}

/// The default save path of a scene: `NAME.edited.vdag` beside it.
pub fn default_save_path(scene: &Path) -> PathBuf {
    scene.with_extension("edited.vdag")
}

impl FileState {
    /// The state at start for `scene`: a recovery prompt (or a pending recovery) when its
    /// autosave is newer; recording when `--record` asks.
    pub fn new(args: &FileArgs, scene: &Path, resolution: u32) -> Result<FileState> {
        let autosave = autosave_path(scene);
        let newer = newer(&autosave, scene);
        let recorder = match &args.record {
            Some(path) => Some(Recorder::create(path)?),
            None => None,
        };
        Ok(FileState {
            open: String::new(),
            save_as: String::new(),
            import: String::new(),
            import_resolution: resolution,
            export: default_save_path(scene)
                .with_extension("vox")
                .display()
                .to_string(),
            record: scene.with_extension("replay.csv").display().to_string(),
            focus: None,
            focused: None,
            pending: (newer && args.recover == Recover::Yes).then_some(Pending::Recover),
            prompt: (newer && args.recover == Recover::Ask).then_some(Prompt::Recover),
            last_error: None,
            autosave_secs: args.autosave_secs,
            last_autosave: Instant::now(),
            autosaved_root: None,
            autosaves: 0,
            recorder,
        })
    }

    /// Records a failed action.
    pub fn fail(&mut self, e: anyhow::Error) {
        self.last_error = Some(format!("{e:#}"));
    }
}

impl Running {
    /// Keys for files and prompts (true: taken). While a prompt is shown it takes every key.
    pub(super) fn file_key(&mut self, code: KeyCode, ctrl: bool, shift: bool) -> bool {
        match self.files.prompt {
            Some(Prompt::Recover) => {
                match code {
                    KeyCode::KeyY | KeyCode::Enter => self.answer(Some(Pending::Recover)),
                    KeyCode::KeyN | KeyCode::Escape => self.answer(None),
                    _ => {}
                }
                return true;
            }
            Some(Prompt::Unsaved) => {
                match code {
                    KeyCode::KeyS => self.answer(Some(Pending::CloseSave)),
                    KeyCode::KeyD => self.answer(Some(Pending::CloseDiscard)),
                    KeyCode::KeyC | KeyCode::Escape => self.answer(None),
                    _ => {}
                }
                return true;
            }
            None => {}
        }
        if code == KeyCode::Escape {
            self.request_close();
            return true;
        }
        if !ctrl {
            return false;
        }
        let field = match code {
            KeyCode::KeyO => Field::Open,
            KeyCode::KeyS if shift => Field::SaveAs,
            KeyCode::KeyS => {
                self.files.pending = Some(Pending::SaveAs(PathBuf::from(&self.save_path)));
                return true;
            }
            KeyCode::KeyI => Field::Import,
            KeyCode::KeyE => Field::Export,
            KeyCode::KeyR if self.files.recorder.is_some() => {
                self.stop_recording();
                return true;
            }
            KeyCode::KeyR => Field::Record,
            _ => return false,
        };
        self.files.focus = Some(field);
        true
    }

    fn answer(&mut self, pending: Option<Pending>) {
        self.files.prompt = None;
        self.files.pending = pending;
    }

    /// The window's close button or Esc: quits at once without unsaved edits; otherwise
    /// writes the autosave (so a kill or an unanswered prompt loses nothing) and asks.
    pub(super) fn request_close(&mut self) {
        if self.doc.unsaved == 0 {
            self.exit = true;
            return;
        }
        if self.files.prompt.is_none() {
            self.files.prompt = Some(Prompt::Unsaved);
            if let Err(e) = self.autosave() {
                self.files.fail(e.context("autosave before the prompt"));
            }
        }
    }

    fn stop_recording(&mut self) {
        if let Some(r) = self.files.recorder.take() {
            self.message = Some(format!(
                "recorded {} lines to {}",
                r.lines(),
                r.path().display()
            ));
        }
    }

    /// The current root as an svdag32 DAG.
    fn current_svdag(&self) -> Result<Svdag> {
        let image = self.doc.dag.download()?;
        Ok(image.to_svdag(self.doc.dag.root())?)
    }

    /// Writes the current root to the scene's autosave file (atomic; the writer of a save,
    /// materials included), leaving the edits unsaved.
    fn autosave(&mut self) -> Result<()> {
        let path = autosave_path(&self.doc.path);
        let unsaved = self.doc.unsaved;
        let result = self.doc.save(&path);
        self.doc.unsaved = unsaved;
        result?;
        self.files.autosaved_root = Some(self.doc.dag.root());
        self.files.last_autosave = Instant::now();
        self.files.autosaves += 1;
        Ok(())
    }

    /// Removes the scene's autosave (its edits are saved or discarded).
    fn remove_autosave(&mut self) -> Result<()> {
        let path = autosave_path(&self.doc.path);
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                Err(anyhow!("removing {}: {e}", path.display()))
            }
            _ => Ok(()),
        }
    }

    /// Saves to `path` (atomic), which becomes the save path; the autosave goes.
    fn save_as(&mut self, path: &Path) -> Result<()> {
        self.doc.save(path)?;
        self.save_path = path.display().to_string();
        self.files.autosaved_root = None;
        self.remove_autosave()?;
        self.message = Some(format!("saved {}", path.display()));
        Ok(())
    }

    /// Replaces the document with `svdag` and its `materials` (named `path`); on error the
    /// current one stays.
    fn replace_scene(
        &mut self,
        (svdag, materials): (Svdag, Option<Materials>),
        path: PathBuf,
        new_camera: bool,
    ) -> Result<()> {
        let svdag = &svdag;
        let doc = Document::load(
            &self.ctx,
            &self.renderer,
            svdag,
            materials,
            path,
            self.doc.dag.undo_depth(),
            self.doc.dag.config().variant,
        )?;
        // Frames in flight still read the old tables.
        self.ctx.wait_idle()?;
        self.doc = doc;
        if new_camera {
            self.input = CameraInput::new(Camera::frame(svdag), scene_size(svdag));
        }
        self.hover = None;
        self.files.autosaved_root = None;
        if self.files.recorder.is_some() {
            self.stop_recording();
            self.files.last_error = Some("the scene changed: recording stopped".into());
        }
        Ok(())
    }

    /// Runs a pending file action and the autosave timer (start of a frame).
    pub(super) fn files_frame(&mut self) {
        if let Some(pending) = self.files.pending.take() {
            let result = self.run_pending(pending);
            match result {
                Ok(()) => self.files.last_error = None,
                Err(e) => {
                    self.message = Some(format!("{e:#}"));
                    self.files.fail(e);
                }
            }
        }
        let every = Duration::from_secs(self.files.autosave_secs);
        let due = self.files.autosave_secs > 0 && self.files.last_autosave.elapsed() >= every;
        if due && self.doc.unsaved > 0 && self.files.autosaved_root != Some(self.doc.dag.root()) {
            if let Err(e) = self.autosave() {
                self.files.fail(e.context("autosave"));
            }
        }
    }

    fn run_pending(&mut self, pending: Pending) -> Result<()> {
        match pending {
            Pending::Open(path) => {
                let scene = load_scene(&path, None)
                    .map_err(|e| e.context(format!("cannot open {}", path.display())))?;
                self.replace_scene(scene, path.clone(), true)?;
                self.save_path = default_save_path(&path).display().to_string();
                self.message = Some(format!("opened {}", path.display()));
            }
            Pending::SaveAs(path) => self
                .save_as(&path)
                .map_err(|e| e.context(format!("cannot save {}", path.display())))?,
            Pending::Import(path, resolution) => {
                if path
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("vdag"))
                {
                    bail!("{} is a .vdag: use Open (Ctrl+O)", path.display());
                }
                let scene = load_scene(&path, (resolution > 0).then_some(resolution))
                    .map_err(|e| e.context(format!("cannot import {}", path.display())))?;
                let side = scene.0.resolution;
                self.replace_scene(scene, path.clone(), true)?;
                self.save_path = default_save_path(&path).display().to_string();
                self.message = Some(format!("imported {} at {side}^3", path.display()));
            }
            Pending::Export(path) => {
                let ext = path
                    .extension()
                    .map(|e| e.to_string_lossy().to_ascii_lowercase());
                let svdag = self.current_svdag()?;
                match ext.as_deref() {
                    // The engine refuses scenes over 256^3 with the reason.
                    Some("vox") => export_vox(&svdag, &path)?,
                    Some("xyz") => export_xyz_u32_file(&svdag, &path)?,
                    _ => bail!(
                        "cannot export {}: the name must end in .vox (MagicaVoxel) or .xyz \
                         (xyz-u32)",
                        path.display()
                    ),
                }
                self.message = Some(format!(
                    "exported {} voxels to {}",
                    svdag.voxel_count(),
                    path.display()
                ));
            }
            Pending::Record(path) => {
                self.start_recording(&path)?;
                self.message = Some(format!("recording to {}", path.display()));
            }
            Pending::Recover => {
                let path = autosave_path(&self.doc.path);
                let recovered = load_autosave(&path)
                    .map_err(|e| e.context(format!("cannot recover {}", path.display())))?;
                let scene = self.doc.path.clone();
                self.replace_scene(recovered, scene, false)?;
                // The recovered edits are not in the scene file yet.
                self.doc.unsaved = 1;
                self.files.autosaved_root = Some(self.doc.dag.root());
                self.message = Some(format!("recovered {}", path.display()));
            }
            Pending::CloseSave => {
                self.save_as(&PathBuf::from(&self.save_path))
                    .map_err(|e| e.context("cannot save before closing"))?;
                self.exit = true;
            }
            Pending::CloseDiscard => {
                self.remove_autosave()?;
                self.exit = true;
            }
        }
        Ok(())
    }

    /// The file fields of the status file.
    pub(super) fn file_status(&self) -> FileStatus<'_> {
        FileStatus {
            scene_path: self.doc.path.display().to_string(),
            save_path: &self.save_path,
            last_error: self.files.last_error.as_deref(),
            prompt: self.files.prompt,
            focused_field: self.files.focused,
            autosave_path: autosave_path(&self.doc.path).display().to_string(),
            autosaves: self.files.autosaves,
            recording: self
                .files
                .recorder
                .as_ref()
                .map(|r| r.path().display().to_string()),
            recorded_lines: self.files.recorder.as_ref().map_or(0, |r| r.lines()),
        }
    }

    /// The File panel and the prompts.
    pub(super) fn files_panel(&mut self, ctx: &egui::Context) {
        let focus = self.files.focus;
        if focus.is_some() {
            // A shortcut unfolds the panel so that its field can take the focus.
            let id = egui::Id::new(FILE_PANEL).with("collapsing");
            let mut state =
                egui::collapsing_header::CollapsingState::load_with_default_open(ctx, id, false);
            state.set_open(true);
            state.store(ctx);
        }
        let mut focused = false;
        let mut has_focus = None;
        egui::Window::new("File")
            .id(egui::Id::new(FILE_PANEL))
            .default_pos([8.0, 420.0])
            .default_open(false)
            .show(ctx, |ui| {
                if let Some(e) = &self.files.last_error {
                    ui.colored_label(egui::Color32::from_rgb(255, 90, 80), e);
                }
                ui.label(format!("scene {}", self.doc.path.display()));
                ui.horizontal(|ui| {
                    if ui.button("save (Ctrl+S)").clicked() {
                        self.files.pending = Some(Pending::SaveAs(PathBuf::from(&self.save_path)));
                    }
                    ui.label(&self.save_path);
                });
                let files = &mut self.files;
                let mut pending = None;
                let mut row = |ui: &mut egui::Ui, field: Field, label: &str, text: &mut String| {
                    ui.horizontal(|ui| {
                        let edit = ui.add(egui::TextEdit::singleline(text).desired_width(220.0));
                        if focus == Some(field) {
                            edit.request_focus();
                            focused |= edit.has_focus();
                        }
                        if edit.has_focus() {
                            has_focus = Some(field);
                        }
                        let enter =
                            edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter));
                        if (ui.button(label).clicked() || enter) && !text.is_empty() {
                            pending = Some((field, PathBuf::from(text.as_str())));
                        }
                    });
                };
                row(ui, Field::Open, "open (Ctrl+O)", &mut files.open);
                row(
                    ui,
                    Field::SaveAs,
                    "save as (Ctrl+Shift+S)",
                    &mut files.save_as,
                );
                row(ui, Field::Import, "import (Ctrl+I)", &mut files.import);
                ui.add(
                    egui::DragValue::new(&mut files.import_resolution)
                        .range(0..=4096)
                        .prefix("import resolution "),
                );
                row(
                    ui,
                    Field::Export,
                    "export .vox/.xyz (Ctrl+E)",
                    &mut files.export,
                );
                match &files.recorder {
                    Some(r) => {
                        ui.label(format!(
                            "recording {} ({} lines)",
                            r.path().display(),
                            r.lines()
                        ));
                    }
                    None => row(ui, Field::Record, "record (Ctrl+R)", &mut files.record),
                }
                let recording = files.recorder.is_some();
                if let Some((field, path)) = pending {
                    files.pending = Some(match field {
                        Field::Open => Pending::Open(path),
                        Field::SaveAs => Pending::SaveAs(path),
                        Field::Import => Pending::Import(path, files.import_resolution),
                        Field::Export => Pending::Export(path),
                        Field::Record => Pending::Record(path),
                    });
                }
                ui.add(
                    egui::DragValue::new(&mut files.autosave_secs)
                        .range(0..=3600)
                        .prefix("autosave every ")
                        .suffix(" s (0: off)"),
                );
                ui.label(format!(
                    "to {} ({} written)",
                    autosave_path(&self.doc.path).display(),
                    files.autosaves
                ));
                if recording && ui.button("stop recording (Ctrl+R)").clicked() {
                    self.stop_recording();
                }
            });
        if focused {
            self.files.focus = None;
        }
        self.files.focused = has_focus;
        let Some(prompt) = self.files.prompt else {
            return;
        };
        egui::Window::new(match prompt {
            Prompt::Recover => "Recover autosave?",
            Prompt::Unsaved => "Unsaved changes",
        })
        .collapsible(false)
        .resizable(false)
        .anchor(egui::Align2::CENTER_CENTER, [0.0, 0.0])
        .show(ctx, |ui| match prompt {
            Prompt::Recover => {
                ui.label(format!(
                    "{} is newer than the scene. Recover it?",
                    autosave_path(&self.doc.path).display()
                ));
                ui.horizontal(|ui| {
                    if ui.button("recover (Y)").clicked() {
                        self.answer(Some(Pending::Recover));
                    }
                    if ui.button("keep the scene (N)").clicked() {
                        self.answer(None);
                    }
                });
            }
            Prompt::Unsaved => {
                ui.label(format!(
                    "{} unsaved edits (kept in {}).",
                    self.doc.unsaved,
                    autosave_path(&self.doc.path).display()
                ));
                ui.horizontal(|ui| {
                    if ui
                        .button(format!("save to {} (S)", self.save_path))
                        .clicked()
                    {
                        self.answer(Some(Pending::CloseSave));
                    }
                    if ui.button("discard (D)").clicked() {
                        self.answer(Some(Pending::CloseDiscard));
                    }
                    if ui.button("cancel (C)").clicked() {
                        self.answer(None);
                    }
                });
            }
        });
    }
}
