//! The CLI's global allocator: the system allocator, counting live heap bytes against the
//! memory limit. An allocation that would pass the limit, or that the system refuses, prints
//! one line, removes this process's temporary files and exits 1 — never Rust's abort.
//!
//! Stable Rust cannot make `handle_alloc_error` return, so a failed `try_reserve` ends the
//! process the same way; the engine checks input-sized allocations against the limit before
//! making them, so this is the last line, reached only by what those checks do not foresee.

use std::alloc::{GlobalAlloc, Layout, System};
use std::fmt::Write;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Live heap bytes.
static LIVE: AtomicUsize = AtomicUsize::new(0);
/// The limit (unlimited until `set_limit`).
static LIMIT: AtomicUsize = AtomicUsize::new(usize::MAX);

/// Sets the heap limit in bytes.
pub fn set_limit(bytes: u64) {
    LIMIT.store(
        usize::try_from(bytes).unwrap_or(usize::MAX),
        Ordering::Relaxed,
    );
}

/// The system allocator with a byte count and a clean out-of-memory exit.
pub struct LimitedAlloc;

/// A fixed buffer that formats without allocating.
struct StackText {
    buf: [u8; 320],
    len: usize,
}

impl Write for StackText {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let n = s.len().min(self.buf.len() - self.len);
        self.buf[self.len..self.len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.len += n;
        Ok(())
    }
}

/// GiB with one decimal.
fn gib(bytes: usize) -> f64 {
    bytes as f64 / (1u64 << 30) as f64
}

/// One line on stderr, temporary files removed, exit 1; allocates nothing.
fn out_of_memory(size: usize, refused_by_system: bool) -> ! {
    let mut text = StackText {
        buf: [0; 320],
        len: 0,
    };
    let live = LIVE.load(Ordering::Relaxed);
    let _ = if refused_by_system {
        writeln!(
            text,
            "error: out of memory: the system refused {:.2} GiB more ({:.2} GiB in use)",
            gib(size),
            gib(live)
        )
    } else {
        writeln!(
            text,
            "error: out of memory: {:.2} GiB more would pass the memory limit of {:.2} GiB \
             ({:.2} GiB in use; --memory-limit)",
            gib(size),
            gib(LIMIT.load(Ordering::Relaxed)),
            gib(live)
        )
    };
    voxdag::atomic_file::remove_temp_files();
    // SAFETY: write and _exit are async-signal-safe and need no heap.
    unsafe {
        libc::write(2, text.buf.as_ptr().cast(), text.len);
        libc::_exit(1);
    }
}

/// Reserves `size` more bytes against the limit or exits.
fn take(size: usize) {
    let before = LIVE.fetch_add(size, Ordering::Relaxed);
    if before.saturating_add(size) > LIMIT.load(Ordering::Relaxed) {
        LIVE.fetch_sub(size, Ordering::Relaxed);
        out_of_memory(size, false);
    }
}

// SAFETY: every call is forwarded to `System` with the same layout; only counts are added.
unsafe impl GlobalAlloc for LimitedAlloc {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        take(layout.size());
        let p = System.alloc(layout);
        if p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            out_of_memory(layout.size(), true);
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        take(layout.size());
        let p = System.alloc_zeroed(layout);
        if p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            out_of_memory(layout.size(), true);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let old = layout.size();
        if new_size > old {
            take(new_size - old);
        }
        let p = System.realloc(ptr, layout, new_size);
        if p.is_null() {
            LIVE.fetch_sub(new_size.saturating_sub(old), Ordering::Relaxed);
            out_of_memory(new_size, true);
        }
        if new_size < old {
            LIVE.fetch_sub(old - new_size, Ordering::Relaxed);
        }
        p
    }
}
