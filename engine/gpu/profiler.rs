//! GPU pass timing with timestamp queries, CPU spans, a summary table and Chrome trace JSON.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use ash::vk;

use super::commands::{CommandsState, Lifecycle};
use super::release::Garbage;
use super::{vk_err, Commands, GpuContext, GpuError};

/// Timestamp queries in the pool (two per pass); passes beyond this before a `resolve` are
/// labelled but not timed.
const QUERY_CAPACITY: u32 = 1024;

/// Timing of one GPU pass.
#[derive(Clone, Debug, PartialEq)]
pub struct PassTiming {
    /// Pass name given to [`Profiler::begin_pass`].
    pub name: String,
    /// GPU time between the pass's begin and end timestamps, in milliseconds.
    pub gpu_ms: f64,
    /// Start on the profiler's CPU clock (ms since [`Profiler::new`]), estimated by aligning
    /// the batch's last GPU timestamp with the moment `resolve` was called.
    pub cpu_start_ms: f64,
}

/// A CPU-side span (upload, readback, ...).
#[derive(Clone, Debug, PartialEq)]
pub struct CpuSpan {
    /// Span name.
    pub name: String,
    /// Start in ms since [`Profiler::new`].
    pub start_ms: f64,
    /// Duration in ms.
    pub dur_ms: f64,
}

/// A pass whose timestamps are written but not yet read back.
struct PendingPass {
    name: String,
    begin_query: Option<u32>,
    end_query: Option<u32>,
    /// The command buffer the pass is recorded in: its timestamps exist only once it finished,
    /// and never if it was dropped unsubmitted.
    lifecycle: Arc<Lifecycle>,
}

/// Times GPU passes (timestamp queries + debug labels) and CPU spans.
///
/// Use: `begin_pass(&mut cmd, "name")` ... `end_pass(&mut cmd)`, submit, then `resolve()`.
/// Passes recorded into a [`Commands`] that is dropped without being submitted (an error path)
/// are discarded, open or closed, so later passes resolve normally.
pub struct Profiler {
    ctx: Arc<GpuContext>,
    pool: vk::QueryPool,
    next_query: u32,
    open: Vec<usize>,
    pending: Vec<PendingPass>,
    passes: Vec<PassTiming>,
    cpu_spans: Vec<CpuSpan>,
    epoch: Instant,
    period_ns: f64,
    valid_mask: u64,
}

impl Profiler {
    /// Creates a profiler; without timestamp support (`timestampValidBits == 0`) passes still get
    /// debug labels but no timings ([`Profiler::is_available`] is false).
    pub fn new(ctx: &Arc<GpuContext>) -> Result<Profiler, GpuError> {
        let info = ctx.info();
        let bits = info.timestamp_valid_bits;
        let pool = if bits == 0 {
            log::warn!("GPU profiling unavailable: the queue has no timestamp support");
            vk::QueryPool::null()
        } else {
            let qi = vk::QueryPoolCreateInfo::default()
                .query_type(vk::QueryType::TIMESTAMP)
                .query_count(QUERY_CAPACITY);
            // SAFETY: valid create info; destroyed in Drop.
            let pool = unsafe { ctx.device.create_query_pool(&qi, None) }
                .map_err(vk_err("vkCreateQueryPool"))?;
            ctx.set_name(pool, "profiler timestamps");
            pool
        };
        Ok(Profiler {
            ctx: Arc::clone(ctx),
            pool,
            next_query: 0,
            open: Vec::new(),
            pending: Vec::new(),
            passes: Vec::new(),
            cpu_spans: Vec::new(),
            epoch: Instant::now(),
            period_ns: info.timestamp_period as f64,
            valid_mask: if bits >= 64 {
                u64::MAX
            } else {
                (1u64 << bits) - 1
            },
        })
    }

    /// Whether GPU timestamps are supported (otherwise passes are only labelled).
    pub fn is_available(&self) -> bool {
        self.pool != vk::QueryPool::null()
    }

    fn now_ms(&self) -> f64 {
        self.epoch.elapsed().as_secs_f64() * 1e3
    }

    fn take_query(&mut self, cmd: &mut Commands<'_>) -> Option<u32> {
        if !self.is_available() || self.next_query >= QUERY_CAPACITY {
            return None;
        }
        let q = self.next_query;
        self.next_query += 1;
        cmd.before_command();
        // SAFETY: resetting then writing query `q` of our pool in the same command buffer.
        unsafe {
            self.ctx
                .device
                .cmd_reset_query_pool(cmd.raw, self.pool, q, 1);
        }
        Some(q)
    }

    /// Opens a named pass: debug label + begin timestamp + an execution-only barrier. Passes may
    /// nest. Must be called outside a render pass instance (the barrier is recorded there).
    pub fn begin_pass(&mut self, cmd: &mut Commands<'_>, name: &str) {
        cmd.begin_label(name);
        let q = self.take_query(cmd);
        if let Some(q) = q {
            // SAFETY: query `q` was reset above in this command buffer; the barrier has no
            // memory or layout part, and callers record passes outside render pass instances.
            unsafe {
                self.ctx.device.cmd_write_timestamp(
                    cmd.raw,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    self.pool,
                    q,
                );
                // lavapipe takes a timestamp at its next flush, and every pipeline barrier
                // flushes: without one, the begin timestamp can land after the pass's first
                // dispatch (the pass reads ~0 ms once a render pass ran on the queue). Source
                // TOP_OF_PIPE waits for nothing, so on real GPUs it orders no work.
                self.ctx.device.cmd_pipeline_barrier(
                    cmd.raw,
                    vk::PipelineStageFlags::TOP_OF_PIPE,
                    vk::PipelineStageFlags::ALL_COMMANDS,
                    vk::DependencyFlags::empty(),
                    &[],
                    &[],
                    &[],
                );
            }
        }
        self.pending.push(PendingPass {
            name: name.to_string(),
            begin_query: q,
            end_query: None,
            lifecycle: Arc::clone(&cmd.lifecycle),
        });
        self.open.push(self.pending.len() - 1);
    }

    /// Forgets open passes whose command buffer was dropped unsubmitted: they can never be closed.
    fn prune_abandoned_open(&mut self) {
        let pending = &self.pending;
        self.open
            .retain(|&i| pending[i].lifecycle.get() != CommandsState::Abandoned);
    }

    /// Closes the innermost open pass: end timestamp + end of its debug label. The pass must have
    /// been opened in the same `cmd`; otherwise this logs a warning and records nothing.
    pub fn end_pass(&mut self, cmd: &mut Commands<'_>) {
        self.prune_abandoned_open();
        let Some(&i) = self.open.last() else {
            log::warn!("Profiler::end_pass without begin_pass");
            return;
        };
        if !Arc::ptr_eq(&self.pending[i].lifecycle, &cmd.lifecycle) {
            log::warn!(
                "Profiler::end_pass: pass '{}' was opened in another command buffer than '{}'",
                self.pending[i].name,
                cmd.name()
            );
            return;
        }
        self.open.pop();
        if self.pending[i].begin_query.is_some() {
            let q = self.take_query(cmd);
            if let Some(q) = q {
                // SAFETY: query `q` was reset above in this command buffer.
                unsafe {
                    self.ctx.device.cmd_write_timestamp(
                        cmd.raw,
                        vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                        self.pool,
                        q,
                    );
                }
            }
            self.pending[i].end_query = q;
        }
        cmd.end_label();
    }

    /// Reads the timestamps of all passes closed since the last call (their command buffers must
    /// have been submitted) and returns their timings, also kept for [`Profiler::table`].
    ///
    /// Passes of command buffers dropped without a submit are discarded. A pass still open, or
    /// closed in a command buffer not submitted yet, is an error that changes nothing: submit
    /// (or drop) that command buffer and call `resolve` again.
    pub fn resolve(&mut self) -> Result<Vec<PassTiming>, GpuError> {
        self.prune_abandoned_open();
        if !self.open.is_empty() {
            return Err(GpuError::InvalidArgument(format!(
                "Profiler::resolve with {} pass(es) still open",
                self.open.len()
            )));
        }
        if let Some(p) = self
            .pending
            .iter()
            .find(|p| p.lifecycle.get() == CommandsState::Recording)
        {
            return Err(GpuError::InvalidArgument(format!(
                "Profiler::resolve: pass '{}' is in a command buffer that was not submitted yet",
                p.name
            )));
        }
        // Wait for the submissions that carry the passes (usually done already).
        let last = self
            .pending
            .iter()
            .filter_map(|p| match p.lifecycle.get() {
                CommandsState::Submitted(v) => Some(v),
                _ => None,
            })
            .max();
        if let Some(v) = last {
            self.ctx.wait_for(v)?;
        }
        let resolved_at = self.now_ms();
        // (name, begin, end) raw timestamps of the finished, timed passes.
        let mut timed = Vec::new();
        let mut read = Ok(());
        for p in &self.pending {
            if p.lifecycle.get() == CommandsState::Abandoned {
                log::debug!("profiler: pass '{}' discarded (never submitted)", p.name);
                continue;
            }
            let (Some(b), Some(e)) = (p.begin_query, p.end_query) else {
                continue;
            };
            match (self.read_query(b), self.read_query(e)) {
                (Ok(tb), Ok(te)) => timed.push((p.name.clone(), tb, te)),
                (Err(err), _) | (_, Err(err)) => {
                    read = Err(err);
                    break;
                }
            }
        }
        // The batch is consumed even if reading failed (device lost?), so that later passes
        // do not inherit the failure.
        self.pending.clear();
        self.next_query = 0;
        read?;
        let last = timed.iter().map(|t| t.2).max().unwrap_or(0);
        let to_ms = self.period_ns / 1e6;
        let out: Vec<PassTiming> = timed
            .into_iter()
            .map(|(name, tb, te)| PassTiming {
                name,
                gpu_ms: te.wrapping_sub(tb) as f64 * to_ms,
                cpu_start_ms: (resolved_at - last.wrapping_sub(tb) as f64 * to_ms).max(0.0),
            })
            .collect();
        self.passes.extend(out.iter().cloned());
        Ok(out)
    }

    /// One timestamp, masked to the valid bits.
    fn read_query(&self, q: u32) -> Result<u64, GpuError> {
        let mut stamp = [0u64];
        // SAFETY: query `q` was reset and written by a command buffer that finished (resolve
        // waited for its timeline value).
        unsafe {
            self.ctx.device.get_query_pool_results(
                self.pool,
                q,
                &mut stamp,
                vk::QueryResultFlags::TYPE_64,
            )
        }
        .map_err(|e| match e {
            vk::Result::NOT_READY => {
                GpuError::InvalidArgument(format!("Profiler::resolve: timestamp {q} not ready"))
            }
            e => vk_err("vkGetQueryPoolResults")(e),
        })?;
        Ok(stamp[0] & self.valid_mask)
    }

    /// Runs `f` and records it as a CPU span named `name`.
    pub fn cpu_span<R>(&mut self, name: &str, f: impl FnOnce() -> R) -> R {
        let start = Instant::now();
        let r = f();
        self.record_cpu_span(name, start, Instant::now());
        r
    }

    /// Records a CPU span measured by the caller.
    pub fn record_cpu_span(&mut self, name: &str, start: Instant, end: Instant) {
        let start_ms = start.saturating_duration_since(self.epoch).as_secs_f64() * 1e3;
        let dur_ms = end.saturating_duration_since(start).as_secs_f64() * 1e3;
        self.cpu_spans.push(CpuSpan {
            name: name.to_string(),
            start_ms,
            dur_ms,
        });
    }

    /// All resolved GPU pass timings so far.
    pub fn passes(&self) -> &[PassTiming] {
        &self.passes
    }

    /// All CPU spans so far.
    pub fn cpu_spans(&self) -> &[CpuSpan] {
        &self.cpu_spans
    }

    /// Forgets all timings and spans.
    pub fn clear(&mut self) {
        self.passes.clear();
        self.cpu_spans.clear();
    }

    /// Per-pass summary: pass, calls, total ms, mean ms (GPU passes, then CPU spans).
    pub fn table(&self) -> String {
        let mut rows: Vec<(String, usize, f64)> = Vec::new();
        let mut add = |name: String, ms: f64| match rows.iter_mut().find(|r| r.0 == name) {
            Some(r) => {
                r.1 += 1;
                r.2 += ms;
            }
            None => rows.push((name, 1, ms)),
        };
        for p in &self.passes {
            add(format!("gpu: {}", p.name), p.gpu_ms);
        }
        for s in &self.cpu_spans {
            add(format!("cpu: {}", s.name), s.dur_ms);
        }
        let width = rows.iter().map(|r| r.0.len()).max().unwrap_or(4).max(4);
        let mut t = String::new();
        if !self.is_available() {
            t.push_str("GPU timestamps unavailable on this device: GPU passes are not timed\n");
        }
        let _ = writeln!(
            t,
            "{:<width$} {:>6} {:>12} {:>12}",
            "pass", "calls", "total ms", "mean ms"
        );
        for (name, calls, total) in rows {
            let _ = writeln!(
                t,
                "{name:<width$} {calls:>6} {total:>12.3} {:>12.3}",
                total / calls as f64
            );
        }
        t
    }

    /// Chrome trace-event JSON (opens in Perfetto / chrome://tracing): GPU passes on tid 1,
    /// CPU spans on tid 2, times in µs.
    pub fn chrome_trace_json(&self) -> String {
        let mut events = Vec::new();
        for p in &self.passes {
            events.push(serde_json::json!({
                "name": p.name, "cat": "gpu", "ph": "X",
                "ts": p.cpu_start_ms * 1e3, "dur": p.gpu_ms * 1e3, "pid": 1, "tid": 1
            }));
        }
        for s in &self.cpu_spans {
            events.push(serde_json::json!({
                "name": s.name, "cat": "cpu", "ph": "X",
                "ts": s.start_ms * 1e3, "dur": s.dur_ms * 1e3, "pid": 1, "tid": 2
            }));
        }
        let meta = [(1, "GPU"), (2, "CPU")].map(|(tid, name)| {
            serde_json::json!({"name": "thread_name", "ph": "M", "pid": 1, "tid": tid,
                               "args": {"name": name}})
        });
        events.extend(meta);
        serde_json::json!({ "traceEvents": events, "displayTimeUnit": "ms" }).to_string()
    }

    /// Writes [`Profiler::chrome_trace_json`] to `path`.
    pub fn write_chrome_trace(&self, path: &Path) -> Result<(), GpuError> {
        std::fs::write(path, self.chrome_trace_json()).map_err(|source| GpuError::Io {
            path: path.to_path_buf(),
            source,
        })
    }
}

impl Drop for Profiler {
    fn drop(&mut self) {
        if self.pool != vk::QueryPool::null() {
            // Submissions writing the pool may still run.
            self.ctx.defer(Garbage::QueryPool(self.pool));
        }
    }
}
