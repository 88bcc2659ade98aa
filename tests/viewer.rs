//! `voxdag view` in a real window on a virtual X server (Xvfb started by each test on a free
//! display): the screenshot equals the headless render, a resize is survived, the window closes
//! cleanly with validation on. Fails (never skips) without Xvfb/xdotool: run tools/setup.sh.

mod common;

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use common::xvfb::{find_window, run, voxdag, wait_exit, xdotool, Xvfb};
use common::{compare, failure_dir, repo, save_png};

/// A small coloured scene: the bundled avocado at 128^3 (lossless colour chunks).
fn scene(dir: &Path) -> PathBuf {
    let path = dir.join("avocado.vdag");
    let mut cmd = voxdag(None);
    cmd.args(["build", "--quiet", "--resolution", "128", "-o"])
        .arg(&path)
        .arg(repo().join("assets/avocado/Avocado.gltf"));
    run(cmd);
    path
}

fn read_png(path: &Path) -> image::RgbaImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
        .to_rgba8()
}

#[test]
fn screenshot_equals_headless_render() {
    let dir = tempfile::tempdir().unwrap();
    let vdag = scene(dir.path());
    let x = Xvfb::start();
    let shot = dir.path().join("shot.png");
    let mut view = voxdag(Some(&x.display));
    view.arg("view")
        .arg(&vdag)
        .args(["--size", "200x150", "--frames", "4", "--screenshot"])
        .arg(&shot);
    run(view);
    let headless = dir.path().join("headless.png");
    let mut render = voxdag(None);
    render
        .arg("render")
        .arg(&vdag)
        .args(["--size", "200x150", "--out"])
        .arg(&headless);
    run(render);
    let (a, b) = (read_png(&shot), read_png(&headless));
    assert_eq!(a.dimensions(), b.dimensions(), "screenshot size");
    // Golden tolerance (tests/render_gpu.rs): at most 0.5% of pixels off by more than 8/255.
    let diff = compare(b.as_raw(), a.as_raw(), 8);
    let allowed = (0.005 * (a.width() * a.height()) as f64) as usize;
    if diff.differing > allowed {
        let out = failure_dir();
        save_png(
            &out.join("viewer.actual.png"),
            a.width(),
            a.height(),
            a.as_raw(),
        );
        save_png(
            &out.join("viewer.diff.png"),
            a.width(),
            a.height(),
            &diff.diff_rgba,
        );
        panic!(
            "screenshot differs from the headless render in {} pixels (allowed {allowed}, max \
             delta {}); wrote viewer.actual.png and viewer.diff.png under {}",
            diff.differing,
            diff.max_delta,
            out.display()
        );
    }
}

#[test]
fn survives_an_external_resize_and_closes_on_escape() {
    let dir = tempfile::tempdir().unwrap();
    let vdag = scene(dir.path());
    let x = Xvfb::start();
    let stats = dir.path().join("stats.json");
    let mut cmd = voxdag(Some(&x.display));
    cmd.arg("view")
        .arg(&vdag)
        .args(["--size", "160x120", "--no-vsync", "--stats-json"])
        .arg(&stats)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    let mut viewer = cmd.spawn().expect("starting voxdag view");
    let id = find_window(&x, "voxdag view", &mut viewer);
    // Let it present a few frames at the first size, then resize from outside (as a window
    // manager would), let it present at the new size, then close it with Esc.
    std::thread::sleep(Duration::from_millis(1500));
    xdotool(&x.display, &["windowsize", &id, "232", "174"]);
    std::thread::sleep(Duration::from_millis(1500));
    xdotool(&x.display, &["windowfocus", "--sync", &id]);
    xdotool(&x.display, &["key", "Escape"]);
    let out = wait_exit(viewer);
    assert!(
        out.status.success(),
        "viewer failed ({}):\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&stats).expect("stats written at exit")).unwrap();
    assert_eq!(report["validation_messages"], 0);
    assert_eq!(
        report["extent"],
        serde_json::json!([232, 174]),
        "final size: {report}"
    );
    assert!(
        report["swapchain_creations"].as_u64().unwrap() >= 2,
        "the swapchain was rebuilt: {report}"
    );
    let extents = report["extents"].as_array().unwrap();
    assert_eq!(extents[0][0], serde_json::json!([160, 120]), "{report}");
}

#[test]
fn frames_exit_is_clean_with_three_frames_in_flight() {
    let dir = tempfile::tempdir().unwrap();
    let vdag = scene(dir.path());
    let x = Xvfb::start();
    let stats = dir.path().join("stats.json");
    let mut view = voxdag(Some(&x.display));
    view.arg("view")
        .arg(&vdag)
        .args([
            "--size",
            "128x96",
            "--frames",
            "12",
            "--frames-in-flight",
            "3",
            "--render-scale",
            "0.5",
            "--stats-json",
        ])
        .arg(&stats);
    let out = run(view);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !stderr.contains("vulkan"),
        "Vulkan messages on stderr:\n{stderr}"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    assert_eq!(report["frames"], 12);
    assert_eq!(report["frames_in_flight"], 3);
    assert_eq!(report["internal"], serde_json::json!([64, 48]));
    assert_eq!(report["validation_messages"], 0);
}

#[test]
fn no_display_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let vdag = scene(dir.path());
    let mut view = voxdag(None);
    view.arg("view").arg(&vdag);
    let out = view.output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");
    assert!(stderr.contains("no display"), "{stderr}");
}
