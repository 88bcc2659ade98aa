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
    /// Xvfb's stderr, quoted when a client cannot connect; removed on drop.
    log: std::path::PathBuf,
    /// Held while the server lives (see `XVFB_START`).
    _one_at_a_time: Option<MutexGuard<'static, ()>>,
}

/// One server per test binary at a time (its tests run in parallel): fewer processes on a loaded
/// machine, and no server's shutdown overlaps another's start.
static XVFB_START: Mutex<()> = Mutex::new(());

impl Xvfb {
    /// Starts `Xvfb -displayfd 1` (the server picks a free display number and prints it once it
    /// accepts connections) and checks that a client can connect; a server that cannot be
    /// reached is replaced, at most 3 times.
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
                "{}: {} ({})",
                x.display,
                String::from_utf8_lossy(&probe.stderr).trim(),
                x.state()
            ));
        }
        panic!("no Xvfb server accepted a connection: {failures:?}");
    }

    /// The server's state for failure messages: running or not, socket file, its stderr.
    pub fn state(&self) -> String {
        let pid = self.child.id();
        // The third field of /proc/<pid>/stat is the state; Z once the server exited.
        let running = std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .map(|stat| stat.split_whitespace().nth(2) != Some("Z"))
            .unwrap_or(false);
        let socket = format!("/tmp/.X11-unix/X{}", &self.display[1..]);
        format!(
            "Xvfb pid {pid} {}, socket {} {}, Xvfb stderr: {:?}",
            if running { "running" } else { "exited" },
            socket,
            if std::path::Path::new(&socket).exists() {
                "present"
            } else {
                "missing"
            },
            std::fs::read_to_string(&self.log)
                .unwrap_or_default()
                .trim()
        )
    }

    fn spawn() -> Xvfb {
        let log = std::env::temp_dir().join(format!(
            "voxdag-test-xvfb-{}-{:?}.log",
            std::process::id(),
            Instant::now()
        ));
        let log_file = std::fs::File::create(&log).expect("creating the Xvfb log");
        // -noreset: by default the server resets when its last client disconnects (the probe
        // below, or a closed viewer), and a client connecting during the reset is refused
        // ("Failed to open connection to X server", seen once under load).
        let mut child = Command::new("Xvfb")
            .args([
                "-displayfd",
                "1",
                "-screen",
                "0",
                "1024x768x24",
                "-nolisten",
                "tcp",
                "-noreset",
            ])
            .stdout(Stdio::piped())
            .stderr(log_file)
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
            log,
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
        let _ = std::fs::remove_file(&self.log);
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
pub fn find_window(x: &Xvfb, name: &str, viewer: &mut Child) -> String {
    let display = &x.display;
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
            panic!(
                "the viewer exited ({status}) before its window appeared on {display} ({}): {stderr}",
                x.state()
            );
        }
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "no viewer window after 60 s"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Whether `child` exits within `limit` (it is not reaped: `wait_exit` still collects it).
pub fn exits_within(child: &mut Child, limit: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if child.try_wait().unwrap().is_some() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    false
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
