//! Wall and on-CPU time of frame-loop phases. Wall time alone overstates what a phase costs on a
//! loaded machine (other threads preempt it); the calling thread's CPU time does not, so the
//! viewer reports both (`docs/viewer.md`).

use std::ops::{AddAssign, Sub};
use std::time::{Duration, Instant};

/// CPU time the calling thread has run (`CLOCK_THREAD_CPUTIME_ID`); zero where unavailable.
pub fn thread_cpu_time() -> Duration {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid out-pointer for the duration of the call.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return Duration::ZERO;
    }
    Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

/// Wall time and the calling thread's CPU time spent in a phase.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PhaseTime {
    /// Elapsed wall-clock time.
    pub wall: Duration,
    /// CPU time of the thread that ran the phase (excludes preemption and blocking).
    pub cpu: Duration,
}

impl AddAssign for PhaseTime {
    fn add_assign(&mut self, other: PhaseTime) {
        self.wall += other.wall;
        self.cpu += other.cpu;
    }
}

impl Sub for PhaseTime {
    type Output = PhaseTime;
    fn sub(self, other: PhaseTime) -> PhaseTime {
        PhaseTime {
            wall: self.wall.saturating_sub(other.wall),
            cpu: self.cpu.saturating_sub(other.cpu),
        }
    }
}

/// A point in time on both clocks; [`PhaseClock::lap`] measures from it to now.
#[derive(Clone, Copy, Debug)]
pub struct PhaseClock {
    wall: Instant,
    cpu: Duration,
}

impl PhaseClock {
    /// Now, on the wall clock and the calling thread's CPU clock.
    pub fn start() -> PhaseClock {
        PhaseClock {
            wall: Instant::now(),
            cpu: thread_cpu_time(),
        }
    }

    /// The time since the last lap (or the start) and restarts there.
    pub fn lap(&mut self) -> PhaseTime {
        let now = PhaseClock::start();
        let time = PhaseTime {
            wall: now.wall - self.wall,
            cpu: now.cpu.saturating_sub(self.cpu),
        };
        *self = now;
        time
    }

    /// The wall-clock instant of the last lap (or the start).
    pub fn instant(&self) -> Instant {
        self.wall
    }
}

impl Sub for PhaseClock {
    type Output = PhaseTime;
    /// The time from `earlier` to `self`.
    fn sub(self, earlier: PhaseClock) -> PhaseTime {
        PhaseTime {
            wall: self.wall.saturating_duration_since(earlier.wall),
            cpu: self.cpu.saturating_sub(earlier.cpu),
        }
    }
}
