//! A private Xvfb server per test and xdotool helpers for the window tests (tests/viewer.rs,
//! tests/editor.rs). Fails (never skips) without Xvfb/xdotool: run tools/setup.sh.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Output, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// A private Xvfb server, terminated on drop.
pub struct Xvfb {
    child: Child,
    /// The display name (":N").
    pub display: String,
    /// Held while the server lives: one server per test binary at a time, so no server's
    /// shutdown (which removes its lock and socket) can race another's start on the same display.
    _one_at_a_time: Option<MutexGuard<'static, ()>>,
}

/// Serialises the Xvfb start-ups of this test binary (its tests run in parallel). An X server
/// picking a display with `-displayfd` takes `/tmp/.X<n>-lock`; a stale lock (left by a server
/// killed with SIGKILL, as these tests did) is removed by whichever starting server sees it, and
/// two servers starting at once can both remove it and both take display n. The test whose server
/// lost the socket then fails with the viewer's "Failed to open connection to X server" before its
/// window appears (reproduced once in 15 runs of this file on the loaded machine).
static XVFB_START: Mutex<()> = Mutex::new(());

impl Xvfb {
    /// Starts `Xvfb -displayfd 1` (the server picks a free display number and prints it once it
    /// accepts connections) and checks that a client can connect; a server that cannot be
    /// reached (another process raced it for the display) is replaced, at most 3 times.
    pub fn start() -> Xvfb {
        let one_at_a_time = XVFB_START.lock().unwrap_or_else(|e| e.into_inner());
        let mut failures = Vec::new();
        for _ in 0..3 {
            let mut x = Xvfb::spawn();
            let probe = Command::new("xdotool")
                .arg("getdisplaygeometry")
                .env("DISPLAY", &x.display)
                .output()
                .unwrap_or_else(|e| panic!("cannot run xdotool ({e}): run tools/setup.sh"));
            if probe.status.success() {
                x._one_at_a_time = Some(one_at_a_time);
                return x;
            }
            failures.push(format!(
                "{}: {}",
                x.display,
                String::from_utf8_lossy(&probe.stderr).trim()
            ));
        }
        panic!("no Xvfb server accepted a connection: {failures:?}");
    }

    fn spawn() -> Xvfb {
        let mut child = Command::new("Xvfb")
            .args([
                "-displayfd",
                "1",
                "-screen",
                "0",
                "1024x768x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("cannot start Xvfb ({e}): run tools/setup.sh (installs xvfb and xdotool)")
            });
        let mut line = String::new();
        BufReader::new(child.stdout.take().expect("piped"))
            .read_line(&mut line)
            .expect("reading Xvfb's display number");
        let number: u32 = line
            .trim()
            .parse()
            .unwrap_or_else(|_| panic!("Xvfb printed {line:?} instead of a display number"));
        Xvfb {
            child,
            display: format!(":{number}"),
            _one_at_a_time: None,
        }
    }
}

impl Drop for Xvfb {
    /// SIGTERM, so the server removes its lock file and socket (SIGKILL after 5 s).
    fn drop(&mut self) {
        // SAFETY: signalling our own child process, not yet reaped (its pid is still ours).
        unsafe {
            libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM);
        }
        let start = Instant::now();
        while matches!(self.child.try_wait(), Ok(None)) {
            if start.elapsed() > Duration::from_secs(5) {
                let _ = self.child.kill();
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.wait();
    }
}

/// Runs `xdotool ARGS`, returning its stdout.
pub fn xdotool(display: &str, args: &[&str]) -> String {
    let out = Command::new("xdotool")
        .args(args)
        .env("DISPLAY", display)
        .output()
        .unwrap_or_else(|e| panic!("cannot run xdotool ({e}): run tools/setup.sh"));
    assert!(
        out.status.success(),
        "xdotool {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Waits (up to 60 s) for a window whose name contains `name` and returns its id.
pub fn find_window(display: &str, name: &str, viewer: &mut Child) -> String {
    let start = Instant::now();
    loop {
        let out = Command::new("xdotool")
            .args(["search", "--name", name])
            .env("DISPLAY", display)
            .output()
            .expect("running xdotool: run tools/setup.sh");
        if let Some(id) = String::from_utf8_lossy(&out.stdout).lines().next() {
            return id.trim().to_string();
        }
        if let Some(status) = viewer.try_wait().unwrap() {
            let mut stderr = String::new();
            if let Some(mut e) = viewer.stderr.take() {
                let _ = std::io::Read::read_to_string(&mut e, &mut stderr);
            }
            panic!("the viewer exited ({status}) before its window appeared: {stderr}");
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no viewer window after 60 s"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Waits (up to 60 s) for the viewer to exit.
pub fn wait_exit(viewer: Child) -> Output {
    let start = Instant::now();
    let mut viewer = viewer;
    while viewer.try_wait().unwrap().is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            let _ = viewer.kill();
            panic!("the viewer did not exit within 60 s of the close request");
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    viewer.wait_with_output().unwrap()
}

/// The CLI with validation on, pinned to no display unless given one.
pub fn voxdag(display: Option<&str>) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_voxdag"));
    cmd.env("VOXDAG_VALIDATION", "1")
        .env_remove("WAYLAND_DISPLAY");
    match display {
        Some(d) => cmd.env("DISPLAY", d),
        None => cmd.env_remove("DISPLAY"),
    };
    cmd
}

/// Runs `cmd`; panics with its output unless it succeeds.
pub fn run(mut cmd: Command) -> Output {
    let out = cmd.output().expect("running voxdag");
    assert!(
        out.status.success(),
        "{cmd:?} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}
