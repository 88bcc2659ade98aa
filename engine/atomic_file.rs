//! Crash-safe file output: a reader never sees a half-written scene, image or report, and no
//! temporary file outlives the process (errors, Ctrl-C, SIGTERM, out of memory).

use std::ffi::{c_char, CString};
use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter};
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::ptr::null_mut;
use std::sync::atomic::{AtomicPtr, Ordering};

/// Temporary files of this process, as C strings a signal handler can unlink without
/// allocating. A slot's string is leaked on purpose: a handler may still be reading it.
static TEMPS: [AtomicPtr<c_char>; 32] = [const { AtomicPtr::new(null_mut()) }; 32];

/// Registers `path` for removal on a signal or out of memory; returns its slot.
fn register_temp(path: &Path) -> Option<usize> {
    let c = CString::new(path.as_os_str().as_bytes()).ok()?.into_raw();
    for (i, slot) in TEMPS.iter().enumerate() {
        if slot
            .compare_exchange(null_mut(), c, Ordering::SeqCst, Ordering::SeqCst)
            .is_ok()
        {
            return Some(i);
        }
    }
    // SAFETY: `c` came from `into_raw` above and was never shared.
    drop(unsafe { CString::from_raw(c) });
    None
}

/// Forgets slot `i` (the file was renamed or removed).
fn unregister_temp(i: usize) {
    TEMPS[i].store(null_mut(), Ordering::SeqCst);
}

/// Removes every temporary file this process is writing. Async-signal-safe (only `unlink`):
/// called from the signal handlers, the out-of-memory path and the panic hook.
pub fn remove_temp_files() {
    for slot in &TEMPS {
        let p = slot.load(Ordering::SeqCst);
        if !p.is_null() {
            // SAFETY: registered strings are valid C strings that are never freed.
            unsafe { libc::unlink(p) };
        }
    }
}

/// Signal handler: remove the temporary files, then die of the same signal.
extern "C" fn on_signal(sig: libc::c_int) {
    remove_temp_files();
    // SAFETY: signal and raise are async-signal-safe.
    unsafe {
        libc::signal(sig, libc::SIG_DFL);
        libc::raise(sig);
    }
}

/// Installs handlers for SIGINT, SIGTERM and SIGHUP that remove this process's temporary
/// files before it dies of the signal.
pub fn install_signal_handlers() {
    for sig in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
        // SAFETY: the handler only calls async-signal-safe functions.
        unsafe {
            let mut action: libc::sigaction = std::mem::zeroed();
            action.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as usize;
            libc::sigemptyset(&mut action.sa_mask);
            libc::sigaction(sig, &action, std::ptr::null_mut());
        }
    }
}

/// Whether `path` is written in place instead of replaced: `-` (stdout), an existing
/// non-regular file (FIFO, device) or anything under /dev or /proc (`/dev/stdout`).
fn written_in_place(path: &Path) -> bool {
    path.as_os_str() == "-"
        || path.starts_with("/dev")
        || path.starts_with("/proc")
        || std::fs::metadata(path).is_ok_and(|m| !m.is_file() && !m.is_dir())
}

/// The folder a new file at `path` goes into.
fn parent_dir(path: &Path) -> PathBuf {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Checks before any work that `path` can be written: `-`, an existing non-directory that is
/// writable, or a new name in an existing, writable folder.
pub fn check_output_path(path: &Path) -> io::Result<()> {
    let fail = |m: String| Err(io::Error::new(io::ErrorKind::InvalidInput, m));
    if path.as_os_str() == "-" {
        return Ok(());
    }
    if path.file_name().is_none() {
        return fail(format!("{}: not a file name", path.display()));
    }
    let writable = |p: &Path| {
        CString::new(p.as_os_str().as_bytes())
            // SAFETY: a valid C string.
            .is_ok_and(|c| unsafe { libc::access(c.as_ptr(), libc::W_OK) } == 0)
    };
    match std::fs::metadata(path) {
        Ok(m) if m.is_dir() => return fail(format!("{} is a directory", path.display())),
        Ok(_) if !writable(path) => return fail(format!("{} is not writable", path.display())),
        Ok(m) if !m.is_file() => return Ok(()), // a FIFO or device: written in place
        _ => {}
    }
    let dir = parent_dir(path);
    if !dir.is_dir() {
        return fail(format!("output folder {} does not exist", dir.display()));
    }
    if !writable(&dir) {
        return fail(format!("output folder {} is not writable", dir.display()));
    }
    Ok(())
}

/// Opens an output that is written in place (see [`written_in_place`]): stdout for `-`, else
/// the existing file, truncated only when it is a regular file.
fn open_in_place(path: &Path) -> io::Result<File> {
    if path.as_os_str() == "-" {
        use std::os::fd::AsFd;
        return Ok(File::from(io::stdout().as_fd().try_clone_to_owned()?));
    }
    let regular = std::fs::metadata(path).is_ok_and(|m| m.is_file());
    OpenOptions::new().write(true).truncate(regular).open(path)
}

/// A new file beside `path`, created exclusively under a random name (a planted file or
/// symlink is never followed) and registered for removal on signals; returns the file, its
/// path (removed when dropped) and its registration slot, to unregister once renamed.
fn create_temp(path: &Path) -> io::Result<(File, tempfile::TempPath, Option<usize>)> {
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "path has no file name"))?;
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(name);
    prefix.push(".tmp-");
    // The name is registered before the file exists: a signal that arrives while the file is
    // being created still removes it (registering after creation left it behind).
    let mut slot = None;
    let (file, tmp) = tempfile::Builder::new()
        .prefix(&prefix)
        .make_in(parent_dir(path), |candidate| {
            let registered = register_temp(candidate);
            let created = OpenOptions::new()
                .write(true)
                .create_new(true)
                .mode(0o666)
                .open(candidate);
            match &created {
                Ok(_) => slot = registered,
                Err(_) => registered.into_iter().for_each(unregister_temp),
            }
            created
        })?
        .into_parts();
    Ok((file, tmp, slot))
}

/// Writes `path` atomically: a new temporary file in the same directory (created exclusively
/// under a random name, so a planted file or symlink is never followed), fsync, rename, fsync
/// the directory. The temporary file is removed on failure, Ctrl-C, SIGTERM and out of memory.
/// `-` writes to stdout; an existing FIFO or device (and `/dev/...`) is written in place,
/// never replaced.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> io::Result<()> {
    if written_in_place(path) {
        let mut out = BufWriter::new(open_in_place(path)?);
        write(&mut out)?;
        return out.into_inner().map_err(|e| e.into_error()).map(drop);
    }
    let (file, tmp, slot) = create_temp(path)?;
    let result = (|| -> io::Result<()> {
        let mut out = BufWriter::new(file);
        write(&mut out)?;
        let file = out.into_inner().map_err(|e| e.into_error())?;
        file.sync_all()?;
        drop(file);
        Ok(())
    })();
    // `TempPath` removes the file when dropped, so every early return cleans up.
    let result = result.and_then(|()| tmp.persist(path).map_err(|e| e.error));
    if let Some(i) = slot {
        unregister_temp(i);
    }
    result?;
    File::open(parent_dir(path))?.sync_all()
}

/// Opens `path` for an output written as it goes that must survive a kill up to its last
/// flush (a session recording): a new file created as in [`write_atomic`] and renamed over
/// `path` at once, so a planted symlink at `path` is replaced, never written through. `-`,
/// FIFOs and devices are written in place.
pub fn create_streamed(path: &Path) -> io::Result<File> {
    if written_in_place(path) {
        return open_in_place(path);
    }
    let (file, tmp, slot) = create_temp(path)?;
    let persisted = tmp.persist(path).map_err(|e| e.error);
    if let Some(i) = slot {
        unregister_temp(i);
    }
    persisted?;
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;
    use std::sync::Mutex;

    /// `remove_temp_files` removes every registered temporary of the process: the tests that
    /// register temporaries (directly or through `write_atomic`) must not run at the same time.
    static REGISTRY: Mutex<()> = Mutex::new(());

    #[test]
    fn writes_whole_file_or_nothing() {
        let _serial = REGISTRY.lock().unwrap_or_else(|p| p.into_inner());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        write_atomic(&path, |w| w.write_all(b"hello")).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"hello");
        let failed = write_atomic(&path, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("disk full"))
        });
        assert!(failed.is_err());
        assert_eq!(
            std::fs::read(&path).unwrap(),
            b"hello",
            "a failed write keeps the old file"
        );
        let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(leftovers.len(), 1, "no temporary file is left behind");
        assert!(write_atomic(Path::new("/"), |_| Ok(())).is_err());
        assert!(check_output_path(dir.path()).is_err(), "a directory");
        assert!(check_output_path(&dir.path().join("no/such/x")).is_err());
        assert!(check_output_path(&path).is_ok());
        assert!(check_output_path(Path::new("-")).is_ok());
    }

    #[test]
    fn registered_temporaries_are_removed() {
        let _serial = REGISTRY.lock().unwrap_or_else(|p| p.into_inner());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.tmp");
        std::fs::write(&path, b"x").unwrap();
        let slot = register_temp(&path).unwrap();
        remove_temp_files();
        unregister_temp(slot);
        assert!(!path.exists());
    }

    #[test]
    fn streamed_output_replaces_a_symlink_and_is_visible_at_once() {
        let _serial = REGISTRY.lock().unwrap_or_else(|p| p.into_inner());
        let dir = tempfile::tempdir().unwrap();
        let victim = dir.path().join("victim");
        std::fs::write(&victim, b"precious").unwrap();
        let path = dir.path().join("session.csv");
        std::os::unix::fs::symlink(&victim, &path).unwrap();
        let mut file = create_streamed(&path).unwrap();
        file.write_all(b"EndFrame\n").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"EndFrame\n");
        assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 2, "no temporary left beside the output");
    }
}
