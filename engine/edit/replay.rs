//! HashDAG replay files (`src/replay.h` of Phyronnaz/HashDAG), read and written unmodified.
//!
//! One action per line: `Name,field,field,...`. Quirks of real files that the reader takes:
//! trailing empty fields (`EndFrame,,,,,,,,,`), `TRUE`/`FALSE` as well as `true`/`false`,
//! integers or decimals for every number, a last line without `\n`, `\r\n` line ends, blank
//! lines. Anything else is an error naming the file and line ([`ReplayError`]); the whole file
//! is parsed and checked before any action is applied, so nothing after a bad line is applied.
//!
//! Positions and radii are scaled by `2^(scene depth - replay depth)` (HashDAG's
//! `scalingFactor`, scene depth = log2 of the grid side), see [`Replay::steps`].

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use thiserror::Error;

use super::tool::{CopyParams, Shape, Tool};

/// Largest replay depth accepted (grids up to 2^30 in the recording application).
pub const MAX_REPLAY_DEPTH: u32 = 30;

/// An error in a replay file.
#[derive(Debug, Error)]
pub enum ReplayError {
    /// A line cannot be parsed or applied.
    #[error("{}:{line}: {reason}", path.display())]
    Line {
        /// The replay file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// The file cannot be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The replay file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The replay depth is outside `0..=MAX_REPLAY_DEPTH`.
    #[error("replay depth {0} outside 0..={MAX_REPLAY_DEPTH}")]
    Depth(u32),
}

/// One replay action, with HashDAG's fields (unscaled).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Action {
    /// Camera position (HashDAG keeps the camera in doubles).
    SetLocation([f64; 3]),
    /// Camera rotation (3x3, rows).
    SetRotation([f64; 9]),
    /// The application's tool state (path, copy source path, copy destination path, radius,
    /// tool id); recorded, not applied.
    SetToolParameters {
        /// Tool position.
        path: [u32; 3],
        /// Copy source position.
        copy_source: [u32; 3],
        /// Copy destination position.
        copy_dest: [u32; 3],
        /// Tool radius.
        radius: f32,
        /// Tool id.
        tool: u32,
    },
    /// Sphere add (`true`) or remove.
    EditSphere {
        /// Centre.
        location: [f32; 3],
        /// Radius.
        radius: f32,
        /// Add or remove.
        add: bool,
    },
    /// Cube add (`true`) or remove.
    EditCube {
        /// Centre.
        location: [f32; 3],
        /// Half-size.
        radius: f32,
        /// Add or remove.
        add: bool,
    },
    /// Copy (10 fields, or 21 with a transform and the swirl settings).
    EditCopy {
        /// Centre of the source cube.
        location: [f32; 3],
        /// Source anchor.
        source: [f32; 3],
        /// Destination anchor.
        dest: [f32; 3],
        /// Half-size of the source cube.
        radius: f32,
        /// The 21-field form: transform (rows), swirl enabled, swirl period.
        transform: Option<([f32; 9], bool, f32)>,
    },
    /// Flood fill.
    EditFill {
        /// Centre.
        location: [f32; 3],
        /// Half-size.
        radius: f32,
    },
    /// Paint.
    EditPaint {
        /// Centre.
        location: [f32; 3],
        /// Radius.
        radius: f32,
    },
    /// Undo the last edit.
    Undo,
    /// Redo the last undone edit.
    Redo,
    /// End of a frame.
    EndFrame,
}

/// An action with its 1-based line number.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplayLine {
    /// Line in the file.
    pub line: usize,
    /// The action.
    pub action: Action,
}

/// A parsed replay file.
#[derive(Clone, Debug, PartialEq)]
pub struct Replay {
    /// The file it came from (for error messages).
    pub path: PathBuf,
    /// Its actions in order.
    pub lines: Vec<ReplayLine>,
}

/// What the editor does for one replay line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// Apply a tool (scaled to the scene).
    Edit(Tool),
    /// Undo.
    Undo,
    /// Redo.
    Redo,
    /// End of a frame.
    EndFrame,
}

fn number(field: &str) -> Result<f32, String> {
    let v: f32 = field
        .parse()
        .map_err(|_| format!("{field:?} is not a number"))?;
    if !v.is_finite() {
        return Err(format!("{field:?} is not a finite number"));
    }
    Ok(v)
}

fn number64(field: &str) -> Result<f64, String> {
    let v: f64 = field
        .parse()
        .map_err(|_| format!("{field:?} is not a number"))?;
    if !v.is_finite() {
        return Err(format!("{field:?} is not a finite number"));
    }
    Ok(v)
}

fn unsigned(field: &str) -> Result<u32, String> {
    let v: f64 = field
        .parse()
        .map_err(|_| format!("{field:?} is not a number"))?;
    if !(v.is_finite() && v >= 0.0 && v <= u32::MAX as f64) {
        return Err(format!("{field:?} is not an unsigned 32-bit number"));
    }
    Ok(v as u32)
}

fn boolean(field: &str) -> Result<bool, String> {
    match field {
        "true" | "TRUE" => Ok(true),
        "false" | "FALSE" => Ok(false),
        _ => Err(format!("{field:?} is not true/false/TRUE/FALSE")),
    }
}

fn vec3(fields: &[&str]) -> Result<[f32; 3], String> {
    Ok([number(fields[0])?, number(fields[1])?, number(fields[2])?])
}

fn parse_action(line: &str) -> Result<Action, String> {
    let mut fields: Vec<&str> = line.split(',').collect();
    let name = fields.remove(0);
    while fields.last() == Some(&"") {
        fields.pop();
    }
    let expect = |counts: &[usize]| -> Result<(), String> {
        if counts.contains(&fields.len()) {
            Ok(())
        } else {
            let want: Vec<String> = counts.iter().map(|c| c.to_string()).collect();
            Err(format!(
                "{name} takes {} fields, the line has {}",
                want.join(" or "),
                fields.len()
            ))
        }
    };
    let f = &fields;
    Ok(match name {
        "SetLocation" => {
            expect(&[3])?;
            Action::SetLocation([number64(f[0])?, number64(f[1])?, number64(f[2])?])
        }
        "SetRotation" => {
            expect(&[9])?;
            let mut m = [0f64; 9];
            for (v, field) in m.iter_mut().zip(f.iter()) {
                *v = number64(field)?;
            }
            Action::SetRotation(m)
        }
        "SetToolParameters" => {
            expect(&[11])?;
            let u = |i: usize| unsigned(f[i]);
            Action::SetToolParameters {
                path: [u(0)?, u(1)?, u(2)?],
                copy_source: [u(3)?, u(4)?, u(5)?],
                copy_dest: [u(6)?, u(7)?, u(8)?],
                radius: number(f[9])?,
                tool: u(10)?,
            }
        }
        "EditSphere" | "EditCube" => {
            expect(&[5])?;
            let (location, radius, add) = (vec3(f)?, number(f[3])?, boolean(f[4])?);
            if name == "EditSphere" {
                Action::EditSphere {
                    location,
                    radius,
                    add,
                }
            } else {
                Action::EditCube {
                    location,
                    radius,
                    add,
                }
            }
        }
        "EditCopy" => {
            expect(&[10, 21])?;
            let transform = if f.len() == 21 {
                let mut m = [0f32; 9];
                for (v, field) in m.iter_mut().zip(&f[10..19]) {
                    *v = number(field)?;
                }
                Some((m, boolean(f[19])?, number(f[20])?))
            } else {
                None
            };
            Action::EditCopy {
                location: vec3(f)?,
                source: vec3(&f[3..])?,
                dest: vec3(&f[6..])?,
                radius: number(f[9])?,
                transform,
            }
        }
        "EditFill" | "EditPaint" => {
            expect(&[4])?;
            let (location, radius) = (vec3(f)?, number(f[3])?);
            if name == "EditFill" {
                Action::EditFill { location, radius }
            } else {
                Action::EditPaint { location, radius }
            }
        }
        "Undo" | "Redo" | "EndFrame" => {
            expect(&[0])?;
            match name {
                "Undo" => Action::Undo,
                "Redo" => Action::Redo,
                _ => Action::EndFrame,
            }
        }
        other => return Err(format!("unknown action {other:?}")),
    })
}

/// HashDAG's `std::to_string(float)`: `%f`, six decimals.
fn float(v: f32) -> String {
    format!("{v:.6}")
}

/// [`float`] of a double (the camera).
fn double(v: f64) -> String {
    format!("{v:.6}")
}

impl Action {
    /// The line HashDAG's `write_csv` writes for this action (without `\n`).
    pub fn to_csv(&self) -> String {
        let mut fields: Vec<String> = Vec::new();
        let name = match self {
            Action::SetLocation(p) => {
                fields.extend(p.iter().map(|&v| double(v)));
                "SetLocation"
            }
            Action::SetRotation(m) => {
                fields.extend(m.iter().map(|&v| double(v)));
                "SetRotation"
            }
            Action::SetToolParameters {
                path,
                copy_source,
                copy_dest,
                radius,
                tool,
            } => {
                for p in [path, copy_source, copy_dest] {
                    fields.extend(p.iter().map(|v| v.to_string()));
                }
                fields.push(float(*radius));
                fields.push(tool.to_string());
                "SetToolParameters"
            }
            Action::EditSphere {
                location,
                radius,
                add,
            }
            | Action::EditCube {
                location,
                radius,
                add,
            } => {
                fields.extend(location.iter().map(|&v| float(v)));
                fields.push(float(*radius));
                fields.push(add.to_string());
                if matches!(self, Action::EditSphere { .. }) {
                    "EditSphere"
                } else {
                    "EditCube"
                }
            }
            Action::EditCopy {
                location,
                source,
                dest,
                radius,
                transform,
            } => {
                for p in [location, source, dest] {
                    fields.extend(p.iter().map(|&v| float(v)));
                }
                fields.push(float(*radius));
                if let Some((m, swirl, period)) = transform {
                    fields.extend(m.iter().map(|&v| float(v)));
                    fields.push(swirl.to_string());
                    fields.push(float(*period));
                }
                "EditCopy"
            }
            Action::EditFill { location, radius } | Action::EditPaint { location, radius } => {
                fields.extend(location.iter().map(|&v| float(v)));
                fields.push(float(*radius));
                if matches!(self, Action::EditFill { .. }) {
                    "EditFill"
                } else {
                    "EditPaint"
                }
            }
            Action::Undo => "Undo",
            Action::Redo => "Redo",
            Action::EndFrame => "EndFrame",
        };
        let mut line = name.to_string();
        for field in fields {
            let _ = write!(line, ",{field}");
        }
        line
    }
}

impl Replay {
    /// Parses replay text; `path` names it in errors.
    pub fn parse(text: &str, path: impl AsRef<Path>) -> Result<Replay, ReplayError> {
        let path = path.as_ref().to_path_buf();
        let mut lines = Vec::new();
        for (i, raw) in text.split('\n').enumerate() {
            let line = raw.strip_suffix('\r').unwrap_or(raw);
            if line.trim().is_empty() {
                continue;
            }
            let action = parse_action(line).map_err(|reason| ReplayError::Line {
                path: path.clone(),
                line: i + 1,
                reason,
            })?;
            lines.push(ReplayLine {
                line: i + 1,
                action,
            });
        }
        Ok(Replay { path, lines })
    }

    /// Reads and parses a replay file (bounded by the memory limit).
    pub fn load(path: &Path) -> Result<Replay, ReplayError> {
        let io = |source| ReplayError::Io {
            path: path.to_path_buf(),
            source,
        };
        let len = std::fs::metadata(path).map_err(io)?.len();
        crate::safety::check_memory(format!("replay {}", path.display()), len)
            .map_err(|e| io(std::io::Error::other(e.to_string())))?;
        let bytes = std::fs::read(path).map_err(io)?;
        let text = String::from_utf8(bytes).map_err(|e| {
            let line = 1 + e.as_bytes()[..e.utf8_error().valid_up_to()]
                .iter()
                .filter(|&&b| b == b'\n')
                .count();
            ReplayError::Line {
                path: path.to_path_buf(),
                line,
                reason: "not UTF-8 text".into(),
            }
        })?;
        Replay::parse(&text, path)
    }

    /// The file in HashDAG's format (one action per line, each line ending in `\n`).
    pub fn to_csv(&self) -> String {
        let mut out = String::new();
        for l in &self.lines {
            out.push_str(&l.action.to_csv());
            out.push('\n');
        }
        out
    }

    /// Writes the file in HashDAG's format (atomically).
    pub fn save(&self, path: &Path) -> Result<(), ReplayError> {
        let text = self.to_csv();
        crate::atomic_file::write_atomic(path, |w| std::io::Write::write_all(w, text.as_bytes()))
            .map_err(|source| ReplayError::Io {
                path: path.to_path_buf(),
                source,
            })
    }

    /// The editor steps for a scene of side `resolution`, with positions and radii scaled by
    /// `2^(log2(resolution) - replay_depth)`; `material` is the material of added, painted and
    /// filled voxels. Every line is checked first (positions inside `[0, N]`, radius in
    /// `(0, 2N]`, invertible copy transform, no swirl): the first bad line is an error.
    pub fn steps(
        &self,
        resolution: u32,
        replay_depth: u32,
        material: u8,
    ) -> Result<Vec<(usize, Step)>, ReplayError> {
        if replay_depth > MAX_REPLAY_DEPTH {
            return Err(ReplayError::Depth(replay_depth));
        }
        let scale = 2f32.powi(resolution.trailing_zeros() as i32 - replay_depth as i32);
        let n = resolution as f32;
        let mut steps = Vec::new();
        for l in &self.lines {
            let bad = |reason: String| ReplayError::Line {
                path: self.path.clone(),
                line: l.line,
                reason,
            };
            let pos = |p: [f32; 3], what: &str| -> Result<[f32; 3], ReplayError> {
                let s = p.map(|v| v * scale);
                if s.iter().all(|v| (0.0..=n).contains(v)) {
                    Ok(s)
                } else {
                    Err(bad(format!(
                        "{what} {p:?} (scaled {s:?}) is outside the {resolution}^3 scene"
                    )))
                }
            };
            let rad = |r: f32| -> Result<f32, ReplayError> {
                let s = r * scale;
                if s > 0.0 && s <= 2.0 * n {
                    Ok(s)
                } else {
                    Err(bad(format!(
                        "radius {r} (scaled {s}) outside (0, {}]",
                        2 * resolution
                    )))
                }
            };
            let step = match l.action {
                Action::SetLocation(_)
                | Action::SetRotation(_)
                | Action::SetToolParameters { .. } => continue,
                Action::EditSphere {
                    location,
                    radius,
                    add,
                }
                | Action::EditCube {
                    location,
                    radius,
                    add,
                } => {
                    let shape = if matches!(l.action, Action::EditSphere { .. }) {
                        Shape::Sphere
                    } else {
                        Shape::Cube
                    };
                    let (center, radius) = (pos(location, "position")?, rad(radius)?);
                    Step::Edit(if add {
                        Tool::Add {
                            shape,
                            center,
                            radius,
                            material,
                        }
                    } else {
                        Tool::Remove {
                            shape,
                            center,
                            radius,
                        }
                    })
                }
                Action::EditCopy {
                    location,
                    source,
                    dest,
                    radius,
                    transform,
                } => {
                    let transform = match transform {
                        None => None,
                        Some((_, true, _)) => {
                            return Err(bad("copy with swirl is not supported".into()))
                        }
                        Some((m, false, _)) => {
                            Some([[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]])
                        }
                    };
                    Step::Edit(Tool::Copy(CopyParams {
                        source: pos(source, "copy source")?,
                        dest: pos(dest, "copy destination")?,
                        center: pos(location, "position")?,
                        radius: rad(radius)?,
                        transform,
                    }))
                }
                Action::EditFill { location, radius } => Step::Edit(Tool::Fill {
                    center: pos(location, "position")?,
                    radius: rad(radius)?,
                    material,
                }),
                Action::EditPaint { location, radius } => Step::Edit(Tool::Paint {
                    center: pos(location, "position")?,
                    radius: rad(radius)?,
                    material,
                }),
                Action::Undo => Step::Undo,
                Action::Redo => Step::Redo,
                Action::EndFrame => Step::EndFrame,
            };
            if let Step::Edit(tool) = &step {
                tool.validate().map_err(|e| bad(e.to_string()))?;
            }
            steps.push((l.line, step));
        }
        Ok(steps)
    }
}
