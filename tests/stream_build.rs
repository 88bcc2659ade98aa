//! The streaming `voxdag build` (docs/scaling.md) writes the same bytes as the in-memory build
//! (`--in-memory`), and `--memory-budget` either refuses or holds the process's peak RSS under
//! the budget.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{repo, shared_data};

/// A scratch folder for this test binary's outputs.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("voxdag-stream-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

/// Builds `input` streamed and in memory with the same `args`; asserts identical files.
fn assert_same(dir: &Path, input: &Path, args: &[&str]) {
    let mut outputs = Vec::new();
    for mode in ["stream", "memory"] {
        let out = dir.join(format!("{mode}.vdag"));
        let mut all: Vec<String> = vec!["-q".into(), "build".into(), input.display().to_string()];
        all.extend(args.iter().map(|a| a.to_string()));
        all.extend(["-o".into(), out.display().to_string()]);
        if mode == "memory" {
            all.push("--in-memory".into());
        }
        let all: Vec<&str> = all.iter().map(String::as_str).collect();
        let result = common::voxdag_cli(&all);
        assert!(
            result.status.success(),
            "{mode} build of {} {args:?} failed: {}",
            input.display(),
            String::from_utf8_lossy(&result.stderr)
        );
        // The summary line says which path ran: a default that fell back to the in-memory
        // build would compare that build with itself.
        let stdout = String::from_utf8_lossy(&result.stdout);
        assert_eq!(
            stdout.contains("streamed"),
            mode == "stream",
            "{mode} build of {} {args:?} took the other path: {stdout}",
            input.display()
        );
        outputs.push(std::fs::read(&out).expect("read output"));
    }
    assert!(
        outputs[0] == outputs[1],
        "streamed and in-memory builds of {} {args:?} differ ({} vs {} bytes)",
        input.display(),
        outputs[0].len(),
        outputs[1].len()
    );
}

#[test]
fn streaming_equals_in_memory_on_small_models() {
    let dir = scratch("small");
    let data = repo().join("tests/data");
    let avocado = repo().join("assets/avocado/Avocado.gltf");
    for r in ["64", "128", "256"] {
        assert_same(&dir, &data.join("teapot.obj"), &["-r", r]);
        assert_same(&dir, &avocado, &["-r", r]);
        assert_same(&dir, &avocado, &["-r", r, "--colors", "lossy"]);
    }
    assert_same(&dir, &data.join("quad.obj"), &["-r", "64"]);
    assert_same(&dir, &data.join("ff3.vox"), &[]);
    for colors in ["raw", "lossless565", "dolonius", "dado"] {
        assert_same(&dir, &avocado, &["-r", "128", "--colors", colors]);
    }
    assert_same(&dir, &avocado, &["-r", "128", "--chunk-depth", "5"]);
    assert_same(&dir, &avocado, &["-r", "128", "--colors", "none"]);
    assert_same(
        &dir,
        &data.join("teapot.obj"),
        &["-r", "64", "--encoding", "ssvdag"],
    );
    assert_same(&dir, &avocado, &["-r", "64", "--encoding", "tsvdag"]);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every shared mesh at 512, 1024 and 2048 with colours (where it has them).
#[test]
fn streaming_equals_in_memory_on_shared_meshes() {
    let Some(data) = shared_data() else {
        return;
    };
    let resolutions = ["512", "1024", "2048"];
    let dir = scratch("shared");
    let meshes = data.join("meshes");
    let tex = data.join("textured");
    let spot_texture = tex.join("spot/spot_texture.png").display().to_string();
    let models: Vec<(PathBuf, Vec<&str>)> = vec![
        (meshes.join("bunny.obj"), vec![]),
        (meshes.join("dragon.obj"), vec![]),
        (meshes.join("buddha.obj"), vec![]),
        (meshes.join("horse.obj"), vec![]),
        (meshes.join("teapot.obj"), vec![]),
        (meshes.join("sponza-dabrovic.obj"), vec![]),
        (
            meshes.join("sponza-crytek/sponza_crytek_noleaf.obj"),
            vec![],
        ),
        (tex.join("Avocado/Avocado.gltf"), vec![]),
        (tex.join("BoomBox/BoomBox.gltf"), vec![]),
        (tex.join("WaterBottle/WaterBottle.gltf"), vec![]),
        (tex.join("apple/food_apple_01_4k.gltf"), vec![]),
        (tex.join("fox/Fox.gltf"), vec![]),
        (
            tex.join("spot/spot_triangulated.obj"),
            vec!["--texture", spot_texture.as_str()],
        ),
    ];
    for r in resolutions {
        for (model, extra) in &models {
            let mut args = vec!["-r", r];
            args.extend(extra.iter().copied());
            assert_same(&dir, model, &args);
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Runs `voxdag` with `args`; returns success, stderr and the child's peak RSS in bytes (from
/// `wait4`, so other tests' children do not count).
// The child is reaped by wait4 (which also reports its rusage), not Child::wait.
#[allow(clippy::zombie_processes)]
fn run_measured(args: &[&str]) -> (bool, String, u64) {
    let child = Command::new(env!("CARGO_BIN_EXE_voxdag"))
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn voxdag");
    let pid = child.id() as libc::pid_t;
    let mut stderr = String::new();
    {
        use std::io::Read;
        let mut pipe = child.stderr.expect("stderr pipe");
        pipe.read_to_string(&mut stderr).expect("read stderr");
    }
    let mut status = 0;
    // SAFETY: an all-zero rusage is valid; wait4 fills it for our own child.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: pid is our unwaited child; status and usage are valid out-pointers.
    let waited = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    assert_eq!(waited, pid, "wait4 failed");
    let ok = libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0;
    (ok, stderr, usage.ru_maxrss as u64 * 1024)
}

#[test]
fn memory_budget_is_kept_or_refused() {
    let dir = scratch("budget");
    let teapot = repo().join("tests/data/teapot.obj").display().to_string();
    let out = dir.join("t.vdag").display().to_string();
    let (mut kept, mut refused) = (0, 0);
    for budget in ["1M", "120M", "160M", "512M"] {
        let bytes = voxdag_budget(budget);
        let (ok, stderr, peak) = run_measured(&[
            "-q",
            "build",
            &teapot,
            "-r",
            "1024",
            "--memory-budget",
            budget,
            "-o",
            &out,
        ]);
        if ok {
            assert!(
                peak <= bytes,
                "budget {budget}: peak RSS {peak} bytes passes the budget"
            );
            kept += 1;
        } else {
            assert!(
                stderr.contains("--memory-budget"),
                "budget {budget}: failed without naming the budget: {stderr}"
            );
            refused += 1;
        }
    }
    assert!(kept > 0 && refused > 0, "kept {kept}, refused {refused}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Bytes of a `--memory-budget` value with an M suffix.
fn voxdag_budget(text: &str) -> u64 {
    text.trim_end_matches('M').parse::<u64>().expect("number") << 20
}
