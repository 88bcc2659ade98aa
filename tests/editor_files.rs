//! The file handling of `voxdag editor` driven by real input on a private Xvfb server with
//! lavapipe, validation on (tools/editor/files.rs, tools/editor/record.rs): opening a corrupt
//! file shows the error and keeps the scene; Save As; unsaved edits survive a close prompt, a
//! kill and a recovery; export to .vox / xyz-u32 round trips and import of the .vox; a recorded
//! session replays (`voxdag edit`, the editor at the fast pace) to the saved file byte for byte.
//! Fails (never skips) without Xvfb/xdotool: run tools/setup.sh.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use common::repo;
use common::xvfb::{find_window, run, voxdag, wait_exit, xdotool, Xvfb};
use serde_json::Value;

/// The bundled avocado at `resolution`^3.
fn scene(dir: &Path, resolution: u32) -> PathBuf {
    let path = dir.join(format!("avocado{resolution}.vdag"));
    let mut cmd = voxdag(None);
    cmd.args([
        "build",
        "--quiet",
        "--resolution",
        &resolution.to_string(),
        "-o",
    ])
    .arg(&path)
    .arg(repo().join("assets/avocado/Avocado.gltf"));
    run(cmd);
    path
}

/// The voxels of a .vdag as `voxdag export-voxels --format xyz-u32` writes them.
fn xyz(file: &Path, out: &Path) -> Vec<u8> {
    let mut cmd = voxdag(None);
    cmd.arg("export-voxels")
        .arg(file)
        .args(["--format", "xyz-u32", "-o"])
        .arg(out);
    run(cmd);
    std::fs::read(out).unwrap()
}

/// The voxels of an xyz-u32 file moved so that their box's minimum corner is 0, sorted.
fn at_origin(xyz: &[u8]) -> Vec<[u32; 3]> {
    let mut voxels: Vec<[u32; 3]> = xyz
        .chunks_exact(12)
        .map(|c| [0, 1, 2].map(|a| u32::from_le_bytes(c[4 * a..4 * a + 4].try_into().unwrap())))
        .collect();
    let min = [0, 1, 2].map(|a| voxels.iter().map(|v| v[a]).min().unwrap_or(0));
    for v in &mut voxels {
        *v = [0, 1, 2].map(|a| v[a] - min[a]);
    }
    voxels.sort_unstable();
    voxels
}

/// A running editor with its status file.
struct Editor {
    child: Child,
    id: String,
    status: PathBuf,
    display: String,
}

impl Editor {
    /// Starts the editor on `scene` in an 800x600 window (internal scale 1/2) with `extra`
    /// arguments.
    fn start(x: &Xvfb, scene: &Path, status: &Path, extra: &[&str]) -> Editor {
        let _ = std::fs::remove_file(status);
        let mut cmd = voxdag(Some(&x.display));
        cmd.arg("editor")
            .arg(scene)
            .args([
                "--size",
                "800x600",
                "--render-scale",
                "0.5",
                "--no-vsync",
                "--radius",
                "8",
                "--status-file",
            ])
            .arg(status)
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().expect("starting voxdag editor");
        let id = find_window(x, "voxdag editor", &mut child);
        Editor {
            child,
            id,
            status: status.to_path_buf(),
            display: x.display.clone(),
        }
    }

    fn status(&self) -> Option<Value> {
        serde_json::from_slice(&std::fs::read(&self.status).ok()?).ok()
    }

    /// Waits (up to 120 s: lavapipe with validation on a loaded machine) until `ok` holds.
    fn wait(&mut self, what: &str, ok: impl Fn(&Value) -> bool) -> Value {
        self.wait_up_to(what, Duration::from_secs(120), &ok)
            .unwrap_or_else(|| {
                panic!(
                    "no status with {what} after 120 s; last: {:?}",
                    self.status()
                )
            })
    }

    /// Presses `key` until the status shows `ok` (at most 3 presses, 40 s apart). A key that
    /// XTEST delivered while the window's focus was still settling can be lost; a key egui
    /// took instead shows in the status's `ui_keys`, which the failure quotes.
    fn press_until(&mut self, key: &str, what: &str, ok: impl Fn(&Value) -> bool) -> Value {
        for _ in 0..3 {
            self.keys(&[key]);
            if let Some(s) = self.wait_up_to(what, Duration::from_secs(40), &ok) {
                return s;
            }
        }
        panic!(
            "no status with {what} after pressing {key} 3 times; last: {:?}",
            self.status()
        )
    }

    /// Polls the status until `ok` holds (None after `limit`); panics if the editor exits.
    fn wait_up_to(
        &mut self,
        what: &str,
        limit: Duration,
        ok: &impl Fn(&Value) -> bool,
    ) -> Option<Value> {
        let start = Instant::now();
        loop {
            if let Some(s) = self.status() {
                if ok(&s) {
                    return Some(s);
                }
            }
            if let Some(code) = self.child.try_wait().unwrap() {
                let mut stderr = String::new();
                if let Some(mut e) = self.child.stderr.take() {
                    let _ = std::io::Read::read_to_string(&mut e, &mut stderr);
                }
                panic!("the editor exited ({code}) while waiting for {what}: {stderr}");
            }
            if start.elapsed() > limit {
                return None;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Waits for two more frames than now (the editor keeps running).
    fn frames_advance(&mut self) {
        let now = self.wait("a frame", |s| s["frame"].as_u64().is_some())["frame"]
            .as_u64()
            .unwrap();
        self.wait("frames advancing", |s| {
            s["frame"].as_u64().unwrap() > now + 2
        });
    }

    fn keys(&self, keys: &[&str]) {
        xdotool(&self.display, &["windowfocus", "--sync", &self.id]);
        let mut args = vec!["key", "--delay", "50"];
        args.extend_from_slice(keys);
        xdotool(&self.display, &args);
    }

    /// Presses `shortcut`, waits for the File panel's `field` to take the keyboard, replaces
    /// its text with `text` and presses Enter.
    fn enter_path(&mut self, shortcut: &str, field: &str, text: &Path) {
        self.keys(&[shortcut]);
        self.wait(&format!("the {field} field focused"), |s| {
            s["focused_field"] == field
        });
        self.keys(&["ctrl+a"]);
        xdotool(
            &self.display,
            &["type", "--delay", "20", &text.display().to_string()],
        );
        self.keys(&["Return"]);
    }

    /// Moves the pointer to (x, y) of the window and waits for a hovered voxel.
    fn hover(&mut self, x: u32, y: u32) {
        xdotool(
            &self.display,
            &[
                "mousemove",
                "--window",
                &self.id,
                &x.to_string(),
                &y.to_string(),
            ],
        );
        self.wait("a hovered voxel", |s| s["hover"].is_array());
    }

    /// A click; waits until the undo depth or the voxel count changed and a count is shown.
    fn click(&mut self) -> Value {
        let before = self.wait("a voxel count", |s| s["voxels"].as_u64().is_some());
        xdotool(&self.display, &["click", "1"]);
        // The voxel count is absent while it is recounted after an edit: wait for the new one.
        self.wait("the edit", |s| {
            s["voxels"].as_u64().is_some()
                && (s["voxels"] != before["voxels"] || s["undo_depth"] != before["undo_depth"])
        })
    }

    /// Waits for the editor to exit and checks it exited cleanly.
    fn exits(self) {
        let out = wait_exit(self.child);
        assert!(
            out.status.success(),
            "editor failed ({}):\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

fn voxels(s: &Value) -> u64 {
    s["voxels"].as_u64().unwrap()
}

#[test]
fn opening_a_corrupt_file_shows_the_error_and_keeps_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let vdag = scene(dir.path(), 128);
    let bytes = std::fs::read(&vdag).unwrap();
    let truncated = dir.path().join("truncated.vdag");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let garbled = dir.path().join("garbled.vdag");
    let mut garbage = bytes.clone();
    for b in &mut garbage[..64] {
        *b ^= 0x5a;
    }
    std::fs::write(&garbled, &garbage).unwrap();
    let x = Xvfb::start();
    let mut ed = Editor::start(&x, &vdag, &dir.path().join("status.json"), &[]);
    let first = ed.wait("a voxel count", |s| s["voxels"].as_u64().is_some());
    assert_eq!(first["scene_path"], vdag.display().to_string());
    assert!(first["last_error"].is_null(), "{first}");
    for bad in [&truncated, &garbled] {
        ed.enter_path("ctrl+o", "open", bad);
        let failed = ed.wait("the open error", |s| {
            s["last_error"]
                .as_str()
                .is_some_and(|e| e.contains(&bad.display().to_string()))
        });
        assert!(
            failed["last_error"]
                .as_str()
                .unwrap()
                .starts_with("cannot open"),
            "{failed}"
        );
        assert_eq!(voxels(&failed), voxels(&first), "{failed}");
        assert_eq!(failed["scene_path"], vdag.display().to_string());
        ed.frames_advance();
    }
    // Save As writes the scene (the voxels of the original file) and clears the error.
    let copy = dir.path().join("copy.vdag");
    ed.enter_path("ctrl+shift+s", "save-as", &copy);
    let saved = ed.wait("the save", |s| s["save_path"] == copy.display().to_string());
    assert!(saved["last_error"].is_null(), "{saved}");
    assert_eq!(
        xyz(&copy, &dir.path().join("copy.xyz")),
        xyz(&vdag, &dir.path().join("scene.xyz"))
    );
    // Opening a good file replaces the scene.
    ed.enter_path("ctrl+o", "open", &copy);
    let opened = ed.wait("the open", |s| {
        s["scene_path"] == copy.display().to_string()
    });
    ed.wait("the voxel count", |s| voxels(s) == voxels(&first));
    assert!(opened["last_error"].is_null(), "{opened}");
    // The new scene survives a resize and a minimise / restore.
    xdotool(&ed.display, &["windowsize", &ed.id, "520", "400"]);
    ed.wait("the new size", |s| {
        s["extent"] == serde_json::json!([520, 400])
    });
    xdotool(&ed.display, &["windowminimize", "--sync", &ed.id]);
    std::thread::sleep(Duration::from_millis(1000));
    xdotool(&ed.display, &["windowmap", "--sync", &ed.id]);
    ed.frames_advance();
    ed.keys(&["Escape"]);
    ed.exits();
}

#[test]
fn unsaved_edits_survive_the_close_prompt_a_kill_and_recovery() {
    let dir = tempfile::tempdir().unwrap();
    let vdag = scene(dir.path(), 128);
    let autosave = PathBuf::from(format!("{}.autosave", vdag.display()));
    let status = dir.path().join("status.json");
    let x = Xvfb::start();
    let mut ed = Editor::start(&x, &vdag, &status, &["--autosave-secs", "1"]);
    let original = voxels(&ed.wait("a voxel count", |s| s["voxels"].as_u64().is_some()));
    ed.hover(400, 300);
    let edited = voxels(&ed.click());
    assert!(edited > original);
    // The timer writes the autosave after the edit.
    let s = ed.wait("an autosave", |s| s["autosaves"].as_u64().unwrap() >= 1);
    assert_eq!(s["autosave_path"], autosave.display().to_string());
    assert!(autosave.is_file());
    // Esc with unsaved edits asks instead of quitting; the editor keeps running.
    ed.press_until("Escape", "the unsaved-changes prompt", |s| {
        s["prompt"] == "unsaved"
    });
    ed.frames_advance();
    // Killed while the prompt is unanswered: the autosave keeps the edit.
    let mut child = ed.child;
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(autosave.is_file());

    // On start the newer autosave is offered; Y recovers it.
    let mut ed = Editor::start(&x, &vdag, &status, &[]);
    let offered = ed.wait("the recovery prompt", |s| {
        s["prompt"] == "recover" && s["voxels"].as_u64().is_some()
    });
    assert_eq!(voxels(&offered), original);
    ed.keys(&["y"]);
    let recovered = ed.wait("the recovered voxels", |s| {
        s["prompt"].is_null() && voxels(s) != original
    });
    assert_eq!(voxels(&recovered), edited, "{recovered}");
    assert_eq!(recovered["unsaved_edits"], 1, "{recovered}");
    // Esc asks again; S saves to the default path, removes the autosave and quits.
    ed.press_until("Escape", "the unsaved-changes prompt", |s| {
        s["prompt"] == "unsaved"
    });
    ed.keys(&["s"]);
    ed.exits();
    let saved = vdag.with_extension("edited.vdag");
    assert!(saved.is_file());
    assert!(!autosave.exists(), "the autosave outlived the save");

    // --recover yes (scripts): a new autosave is loaded without a prompt; D discards it.
    let mut ed = Editor::start(&x, &saved, &status, &["--autosave-secs", "1"]);
    ed.hover(400, 300);
    let again = voxels(&ed.click());
    ed.wait("an autosave", |s| s["autosaves"].as_u64().unwrap() >= 1);
    let mut child = ed.child;
    child.kill().unwrap();
    child.wait().unwrap();
    let mut ed = Editor::start(&x, &saved, &status, &["--recover", "yes"]);
    let s = ed.wait("the recovered count", |s| voxels(s) == again);
    assert!(s["prompt"].is_null(), "{s}");
    ed.press_until("Escape", "the unsaved-changes prompt", |s| {
        s["prompt"] == "unsaved"
    });
    ed.keys(&["d"]);
    ed.exits();
    assert!(!PathBuf::from(format!("{}.autosave", saved.display())).exists());
}

#[test]
fn export_round_trips_and_import_reads_the_vox() {
    let dir = tempfile::tempdir().unwrap();
    let vdag = scene(dir.path(), 128);
    let x = Xvfb::start();
    let status = dir.path().join("status.json");
    let mut ed = Editor::start(&x, &vdag, &status, &[]);
    let original = ed.wait("a voxel count", |s| s["voxels"].as_u64().is_some());
    ed.hover(400, 300);
    let edited = voxels(&ed.click());
    assert!(edited > voxels(&original));
    let (vox, raw, saved) = (
        dir.path().join("out.vox"),
        dir.path().join("out.xyz"),
        dir.path().join("saved.vdag"),
    );
    for path in [&vox, &raw] {
        ed.enter_path("ctrl+e", "export", path);
        ed.wait("the export", |s| {
            s["message"].as_str().is_some_and(|m| {
                m.starts_with("exported") && m.contains(&path.display().to_string())
            })
        });
    }
    ed.enter_path("ctrl+shift+s", "save-as", &saved);
    ed.wait("the save", |s| s["unsaved_edits"] == 0);
    // The xyz-u32 export equals `voxdag export-voxels` of the saved scene.
    let reference = xyz(&saved, &dir.path().join("reference.xyz"));
    assert_eq!(reference.len() as u64, 12 * edited);
    assert!(
        std::fs::read(&raw).unwrap() == reference,
        "xyz-u32 export differs"
    );
    // The .vox holds the same voxels: built back into a .vdag it exports the same xyz, up to
    // the translation of the .vox importer (it moves the occupied box's corner to 0).
    let from_vox = dir.path().join("from-vox.vdag");
    let mut cmd = voxdag(None);
    cmd.args(["build", "--quiet", "-o"])
        .arg(&from_vox)
        .arg(&vox);
    run(cmd);
    assert!(
        at_origin(&xyz(&from_vox, &dir.path().join("from-vox.xyz"))) == at_origin(&reference),
        ".vox export does not round trip"
    );
    // Import (Ctrl+I) reads the .vox back at the panel's resolution (the scene's, 128).
    ed.enter_path("ctrl+i", "import", &vox);
    let imported = ed.wait("the import", |s| {
        s["scene_path"] == vox.display().to_string()
    });
    assert!(imported["last_error"].is_null(), "{imported}");
    ed.wait("the imported count", |s| voxels(s) == edited);
    // An unknown extension is refused with the reason.
    let bad = dir.path().join("out.obj");
    ed.enter_path("ctrl+e", "export", &bad);
    ed.wait("the refusal", |s| {
        s["last_error"].as_str().is_some_and(|e| e.contains(".vox"))
    });
    assert!(!bad.exists());
    ed.keys(&["Escape"]);
    ed.exits();

    // A 512^3 scene is refused as .vox (MagicaVoxel holds 256^3) with the reason.
    let big = scene(dir.path(), 512);
    let mut ed = Editor::start(&x, &big, &status, &[]);
    ed.wait("a voxel count", |s| s["voxels"].as_u64().is_some());
    let big_vox = dir.path().join("big.vox");
    ed.enter_path("ctrl+e", "export", &big_vox);
    let refused = ed.wait("the refusal", |s| s["last_error"].is_string());
    assert!(
        refused["last_error"].as_str().unwrap().contains("256^3"),
        "{refused}"
    );
    assert!(!big_vox.exists());
    ed.keys(&["Escape"]);
    ed.exits();
}

#[test]
fn a_recorded_session_replays_to_the_saved_file() {
    let dir = tempfile::tempdir().unwrap();
    let vdag = scene(dir.path(), 128);
    let (record, saved) = (
        dir.path().join("session.csv"),
        dir.path().join("saved.vdag"),
    );
    let x = Xvfb::start();
    let status = dir.path().join("status.json");
    let record_arg = record.display().to_string();
    let save_arg = saved.display().to_string();
    let mut ed = Editor::start(
        &x,
        &vdag,
        &status,
        &["--record", &record_arg, "--save", &save_arg],
    );
    ed.hover(400, 300);
    ed.click();
    // Fly a little (camera lines), then remove with a cube, undo, redo, remove a sphere.
    xdotool(&ed.display, &["windowfocus", "--sync", &ed.id]);
    xdotool(&ed.display, &["keydown", "w"]);
    std::thread::sleep(Duration::from_millis(400));
    xdotool(&ed.display, &["keyup", "w"]);
    ed.keys(&["4"]);
    ed.hover(420, 310);
    ed.click();
    ed.keys(&["ctrl+z"]);
    ed.wait("the undo", |s| s["undo_depth"] == 1);
    ed.keys(&["ctrl+y"]);
    ed.wait("the redo", |s| s["undo_depth"] == 2);
    ed.keys(&["2"]);
    ed.hover(430, 290);
    ed.click();
    ed.keys(&["ctrl+s"]);
    let s = ed.wait("the save", |s| s["unsaved_edits"] == 0);
    assert!(s["recorded_lines"].as_u64().unwrap() > 0, "{s}");
    ed.keys(&["Escape"]);
    ed.exits();
    let text = std::fs::read_to_string(&record).unwrap();
    for name in [
        "SetLocation,",
        "SetRotation,",
        "EditSphere,",
        "EditCube,",
        "Undo\n",
        "Redo\n",
        "EndFrame\n",
    ] {
        assert!(text.contains(name), "no {name:?} line in the recording");
    }
    let ours = std::fs::read(&saved).unwrap();
    // `voxdag edit` (GPU and CPU) of the recording writes the same file.
    for cpu in [false, true] {
        let out = dir.path().join(format!("edit-{cpu}.vdag"));
        let mut cmd = voxdag(None);
        cmd.arg("edit").arg(&vdag).arg("--replay").arg(&record);
        if cpu {
            cmd.arg("--cpu");
        }
        cmd.arg("-o").arg(&out);
        run(cmd);
        assert!(
            std::fs::read(&out).unwrap() == ours,
            "`voxdag edit` (cpu: {cpu}) of the recording differs from the editor's save"
        );
    }
    // And the editor playing it as fast as it can.
    let replayed = dir.path().join("replayed.vdag");
    let mut cmd = voxdag(Some(&x.display));
    cmd.arg("editor")
        .arg(&vdag)
        .args(["--size", "200x150", "--replay-pace", "fast", "--replay"])
        .arg(&record)
        .arg("--exit-after-replay")
        .arg("--save")
        .arg(&replayed);
    run(cmd);
    assert!(
        std::fs::read(&replayed).unwrap() == ours,
        "the editor's fast replay of the recording differs from its save"
    );
}
