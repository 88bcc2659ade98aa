//! Limits for untrusted input: the memory limit that every input-sized allocation is checked
//! against first, and quiet panics inside third-party parsers (see `docs/security.md`).

use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

/// The memory limit in bytes; 0 until set or first read (then the default).
static MEMORY_LIMIT: AtomicU64 = AtomicU64::new(0);

/// An allocation that grows with the input would pass the memory limit.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{what} needs {}, the memory limit is {} (--memory-limit)", human_bytes(*.needed), human_bytes(*.limit))]
pub struct MemoryError {
    /// What needed the memory (e.g. "glTF accessor 0").
    pub what: String,
    /// Bytes it needs.
    pub needed: u64,
    /// The limit in force.
    pub limit: u64,
}

/// "48.0 GiB", "512 B": binary units, one decimal.
pub fn human_bytes(bytes: u64) -> String {
    const UNITS: [&str; 6] = ["KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    if bytes < 1024 {
        return format!("{bytes} B");
    }
    let mut value = bytes as f64 / 1024.0;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < UNITS.len() {
        value /= 1024.0;
        unit += 1;
    }
    format!("{value:.1} {}", UNITS[unit])
}

/// Physical memory in bytes (sysconf), `u64::MAX` if unknown.
fn physical_memory() -> u64 {
    // SAFETY: sysconf has no preconditions.
    let (pages, size) = unsafe {
        (
            libc::sysconf(libc::_SC_PHYS_PAGES),
            libc::sysconf(libc::_SC_PAGESIZE),
        )
    };
    if pages <= 0 || size <= 0 {
        return u64::MAX;
    }
    (pages as u64).saturating_mul(size as u64)
}

/// The cgroup (v2, else v1) memory limit of this process, `u64::MAX` if none.
fn cgroup_memory_limit() -> u64 {
    for file in [
        "/sys/fs/cgroup/memory.max",
        "/sys/fs/cgroup/memory/memory.limit_in_bytes",
    ] {
        if let Ok(text) = std::fs::read_to_string(file) {
            if let Ok(v) = text.trim().parse::<u64>() {
                return v;
            }
        }
    }
    u64::MAX
}

/// The soft RLIMIT_AS of this process, `u64::MAX` if unlimited.
fn address_space_limit() -> u64 {
    let mut limit = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: `limit` is a valid rlimit to write into.
    if unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut limit) } != 0
        || limit.rlim_cur == libc::RLIM_INFINITY
    {
        return u64::MAX;
    }
    limit.rlim_cur
}

/// The default memory limit: the smallest of physical RAM, the cgroup limit and RLIMIT_AS.
pub fn default_memory_limit() -> u64 {
    physical_memory()
        .min(cgroup_memory_limit())
        .min(address_space_limit())
}

/// Sets the memory limit (`--memory-limit`); 0 restores the default.
pub fn set_memory_limit(bytes: u64) {
    MEMORY_LIMIT.store(bytes, Ordering::Relaxed);
}

/// The memory limit in force (the default until [`set_memory_limit`] is called).
pub fn memory_limit() -> u64 {
    match MEMORY_LIMIT.load(Ordering::Relaxed) {
        0 => {
            let limit = default_memory_limit();
            MEMORY_LIMIT.store(limit, Ordering::Relaxed);
            limit
        }
        limit => limit,
    }
}

/// Checks, before allocating, that `bytes` for `what` fit the memory limit.
pub fn check_memory(what: impl std::fmt::Display, bytes: u64) -> Result<(), MemoryError> {
    let limit = memory_limit();
    if bytes > limit {
        return Err(MemoryError {
            what: what.to_string(),
            needed: bytes,
            limit,
        });
    }
    Ok(())
}

/// `count` elements of `T` in bytes, saturating (an overflow is simply too much).
pub fn bytes_of<T>(count: u64) -> u64 {
    count.saturating_mul(std::mem::size_of::<T>() as u64)
}

/// An empty vector with room for `count` elements, checked against the memory limit and
/// reserved fallibly: an error instead of an abort when the sizes come from the input.
pub fn try_vec<T>(what: impl std::fmt::Display, count: u64) -> Result<Vec<T>, MemoryError> {
    let bytes = bytes_of::<T>(count);
    check_memory(&what, bytes)?;
    let mut v = Vec::new();
    v.try_reserve_exact(count as usize)
        .map_err(|_| MemoryError {
            what: what.to_string(),
            needed: bytes,
            limit: memory_limit(),
        })?;
    Ok(v)
}

thread_local! {
    /// Depth of [`catch_quietly`] calls on this thread.
    static CATCHING: Cell<u32> = const { Cell::new(0) };
}

/// True while this thread runs code whose panics are caught and turned into errors: a panic
/// hook stays silent then.
pub fn catching_panics() -> bool {
    CATCHING.with(|c| c.get() > 0)
}

/// Runs `f`, turning a panic into `Err(message)`; the panic hook of the CLI prints nothing
/// meanwhile (see [`catching_panics`]).
pub fn catch_quietly<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    CATCHING.with(|c| c.set(c.get() + 1));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    CATCHING.with(|c| c.set(c.get() - 1));
    result.map_err(|e| {
        e.downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| e.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "parser panicked".to_string())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_and_messages() {
        assert_eq!(human_bytes(512), "512 B");
        assert_eq!(human_bytes(48 << 30), "48.0 GiB");
        assert_eq!(human_bytes(3 << 29), "1.5 GiB");
        assert!(default_memory_limit() > 1 << 20);
        let e = MemoryError {
            what: "glTF accessor 0".into(),
            needed: 48 << 30,
            limit: 3 << 29,
        };
        assert_eq!(
            e.to_string(),
            "glTF accessor 0 needs 48.0 GiB, the memory limit is 1.5 GiB (--memory-limit)"
        );
        assert!(check_memory("x", u64::MAX).is_err());
        assert!(try_vec::<u64>("y", u64::MAX / 2).is_err());
        assert_eq!(catch_quietly(|| 3), Ok(3));
        let quiet = catch_quietly(|| {
            assert!(catching_panics());
            panic!("boom")
        });
        assert_eq!(quiet, Err("boom".to_string()));
        assert!(!catching_panics());
    }
}
