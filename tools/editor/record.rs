//! Session recording and replay pacing of `voxdag editor`: the session written as a HashDAG
//! replay CSV (`--record`, the File panel) that `voxdag edit --replay` and the editor's own
//! `--replay` read back, and the replay played at its recorded pace or as fast as possible.
//! A child module of the editor: it reaches the editor's private state. See docs/editor.md.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use clap::ValueEnum;
use glam::Vec3;
use voxdag::atomic_file::create_streamed;
use voxdag::edit::replay::{Action, Replay, Step};
use voxdag::edit::tool::Tool;
use voxdag::render::Camera;

use super::{EditInput, Running};

/// Edit time one frame of a `fast` replay may spend before the frame is drawn.
const FAST_FRAME_BUDGET: Duration = Duration::from_millis(50);

/// How `--replay` is paced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Pace {
    /// One frame per `EndFrame` line (the pace it was recorded at).
    Recorded,
    /// As many lines per frame as fit in 50 ms of edits (`EndFrame` ignored).
    Fast,
}

/// One entry of a replay as the editor plays it: a step, or a camera line.
#[derive(Clone, Copy, Debug)]
enum Play {
    Step(usize, Step),
    Location([f64; 3]),
    Rotation([f64; 9]),
}

/// A replay's steps with its camera lines, in file order.
#[derive(Default)]
pub struct Playlist {
    items: std::vec::IntoIter<Play>,
    /// Lines not yet played.
    left: usize,
}

impl Playlist {
    /// The `steps` of `replay` (from [`Replay::steps`]) with its `SetLocation` / `SetRotation`
    /// lines merged in by line number.
    pub fn new(replay: &Replay, steps: Vec<(usize, Step)>) -> Playlist {
        let mut items: Vec<(usize, Play)> = steps
            .into_iter()
            .map(|(line, step)| (line, Play::Step(line, step)))
            .collect();
        for l in &replay.lines {
            match l.action {
                Action::SetLocation(p) => items.push((l.line, Play::Location(p))),
                Action::SetRotation(m) => items.push((l.line, Play::Rotation(m))),
                _ => {}
            }
        }
        items.sort_by_key(|(line, _)| *line);
        let left = items.len();
        Playlist {
            items: items
                .into_iter()
                .map(|(_, p)| p)
                .collect::<Vec<_>>()
                .into_iter(),
            left,
        }
    }

    /// Whether the replay has anything to play.
    pub fn is_empty(&self) -> bool {
        self.left == 0
    }
}

/// A session being written as a HashDAG replay CSV. Lines are flushed at the end of every frame,
/// so a killed editor leaves the recording up to its last frame.
pub struct Recorder {
    path: PathBuf,
    out: BufWriter<File>,
    /// The camera last written.
    camera: Option<Camera>,
    /// Lines written.
    lines: usize,
}

impl Recorder {
    /// Starts a recording at `path` (replaced, never written through a symlink).
    pub fn create(path: &Path) -> Result<Recorder> {
        let file = create_streamed(path)
            .with_context(|| format!("cannot record to {}", path.display()))?;
        Ok(Recorder {
            path: path.to_path_buf(),
            out: BufWriter::new(file),
            camera: None,
            lines: 0,
        })
    }

    /// The file recorded to.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Lines written so far.
    pub fn lines(&self) -> usize {
        self.lines
    }

    /// Writes one action.
    pub fn action(&mut self, action: &Action) -> Result<()> {
        writeln!(self.out, "{}", action.to_csv())
            .with_context(|| format!("recording to {}", self.path.display()))?;
        self.lines += 1;
        Ok(())
    }

    /// Ends a frame: the camera (`SetLocation` / `SetRotation`) when it moved, `EndFrame`, and a
    /// flush.
    pub fn end_frame(&mut self, camera: &Camera) -> Result<()> {
        if self.camera.as_ref() != Some(camera) {
            let b = camera.basis();
            let mut rows = [0f64; 9];
            for (i, row) in [b.right, b.up, b.forward].iter().enumerate() {
                for a in 0..3 {
                    rows[3 * i + a] = row[a] as f64;
                }
            }
            self.action(&Action::SetLocation(camera.eye.map(|v| v as f64)))?;
            self.action(&Action::SetRotation(rows))?;
            self.camera = Some(*camera);
        }
        self.action(&Action::EndFrame)?;
        self.out
            .flush()
            .with_context(|| format!("recording to {}", self.path.display()))
    }
}

/// The replay line of an edit.
pub fn action_of(tool: &Tool) -> Action {
    use voxdag::edit::tool::Shape;
    let shaped = |shape: Shape, location: [f32; 3], radius: f32, add: bool| match shape {
        Shape::Sphere => Action::EditSphere {
            location,
            radius,
            add,
        },
        Shape::Cube => Action::EditCube {
            location,
            radius,
            add,
        },
    };
    match *tool {
        Tool::Add {
            shape,
            center,
            radius,
            ..
        } => shaped(shape, center, radius, true),
        Tool::Remove {
            shape,
            center,
            radius,
        } => shaped(shape, center, radius, false),
        Tool::Paint { center, radius, .. } => Action::EditPaint {
            location: center,
            radius,
        },
        Tool::Fill { center, radius, .. } => Action::EditFill {
            location: center,
            radius,
        },
        Tool::Copy(c) => Action::EditCopy {
            location: c.center,
            source: c.source,
            dest: c.dest,
            radius: c.radius,
            transform: c.transform.map(|m| {
                let rows = [
                    m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
                ];
                (rows, false, 0.0)
            }),
        },
    }
}

/// `tool` as a replay of its recorded line applies it in a scene of side `resolution` (the
/// CSV's six decimals round the radius): what the editor applies while recording, so that the
/// recording replays to the same voxels. An edit the replay format cannot hold (a centre outside
/// the scene) is an error.
pub fn as_replayed(tool: &Tool, resolution: u32) -> Result<Tool> {
    let material = match *tool {
        Tool::Add { material, .. } | Tool::Paint { material, .. } | Tool::Fill { material, .. } => {
            material
        }
        Tool::Remove { .. } | Tool::Copy(_) => 0,
    };
    let line = action_of(tool).to_csv();
    let steps = Replay::parse(&line, "the recording")?.steps(
        resolution,
        resolution.trailing_zeros(),
        material,
    )?;
    match steps.first() {
        Some((_, Step::Edit(t))) => Ok(*t),
        _ => anyhow::bail!("{line:?} does not replay as an edit"),
    }
}

impl Running {
    /// Starts recording to `path` (stops a recording in progress).
    pub(super) fn start_recording(&mut self, path: &Path) -> Result<()> {
        self.files.recorder = None;
        self.files.recorder = Some(Recorder::create(path)?);
        Ok(())
    }

    /// The tool to apply for `tool`: itself, or while recording its replayed form (None, with
    /// the reason shown, when the recording cannot hold it).
    pub(super) fn recordable(&mut self, tool: &Tool) -> Option<Tool> {
        if self.files.recorder.is_none() {
            return Some(*tool);
        }
        match as_replayed(tool, self.doc.dag.resolution()) {
            Ok(t) => Some(t),
            Err(e) => {
                self.message = Some(format!("edit not applied (cannot be recorded): {e:#}"));
                None
            }
        }
    }

    /// Records `action` when recording; a write error stops the recording.
    pub(super) fn record(&mut self, action: Action) {
        if let Some(r) = &mut self.files.recorder {
            if let Err(e) = r.action(&action) {
                self.files.fail(e.context("recording stopped"));
                self.files.recorder = None;
            }
        }
    }

    /// End of a frame for the recording.
    pub(super) fn record_frame(&mut self) {
        if let Some(r) = &mut self.files.recorder {
            if let Err(e) = r.end_frame(&self.input.camera) {
                self.files.fail(e.context("recording stopped"));
                self.files.recorder = None;
            }
        }
    }

    /// Plays the replay up to its next `EndFrame` (`recorded`) or for 50 ms of edits (`fast`);
    /// sets `replay_done` at its end. Edits are recorded when recording.
    pub(super) fn replay_frame(&mut self, pace: Pace) -> Result<()> {
        let start = Instant::now();
        while let Some(play) = self.steps.items.next() {
            self.steps.left -= 1;
            match play {
                Play::Location(p) => {
                    let c = &mut self.input.camera;
                    let offset = Vec3::from(c.target) - Vec3::from(c.eye);
                    c.eye = p.map(|v| v as f32);
                    c.target = (Vec3::from(c.eye) + offset).to_array();
                }
                Play::Rotation(m) => {
                    let c = &mut self.input.camera;
                    let distance = (Vec3::from(c.target) - Vec3::from(c.eye)).length().max(1.0);
                    let forward = Vec3::new(m[6] as f32, m[7] as f32, m[8] as f32);
                    c.target =
                        (Vec3::from(c.eye) + forward.normalize_or_zero() * distance).to_array();
                    c.up = [m[3] as f32, m[4] as f32, m[5] as f32];
                }
                Play::Step(line, Step::Edit(tool)) => {
                    self.ctx.wait_idle()?;
                    self.doc
                        .dag
                        .edit(&tool, None)
                        .with_context(|| format!("replay line {line}"))?;
                    self.doc.undo = (self.doc.undo + 1).min(self.doc.dag.undo_depth());
                    self.doc.redo = 0;
                    self.doc.unsaved += 1;
                    self.edit_input = Some(EditInput::frame(Instant::now()));
                    self.record(action_of(&tool));
                    if pace == Pace::Fast && start.elapsed() >= FAST_FRAME_BUDGET {
                        return Ok(());
                    }
                }
                Play::Step(_, Step::Undo) => self.undo(),
                Play::Step(_, Step::Redo) => self.redo(),
                Play::Step(_, Step::EndFrame) => {
                    if pace == Pace::Recorded {
                        return Ok(());
                    }
                }
            }
        }
        self.replay_done = true;
        Ok(())
    }
}
