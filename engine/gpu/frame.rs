//! Frames in flight: a ring of N slots, each remembering the timeline value of the last
//! submission made for it. Starting a frame waits only for its own slot's previous frame, so the
//! host records frame `n` while the GPU still runs frames `n - 1 .. n - N + 1`.

use std::sync::Arc;

use super::{GpuContext, GpuError, Submission};

/// Frames in flight when not told otherwise.
pub const DEFAULT_FRAMES_IN_FLIGHT: usize = 2;

/// N frames in flight over the context's timeline semaphore.
#[derive(Debug)]
pub struct FrameRing {
    ctx: Arc<GpuContext>,
    /// Timeline value of the last submission of each slot (0: none yet).
    slots: Vec<u64>,
    /// Frames begun so far.
    frame: u64,
}

impl FrameRing {
    /// A ring of `frames_in_flight` slots (at least 1; 2 or 3 is usual).
    pub fn new(ctx: &Arc<GpuContext>, frames_in_flight: usize) -> Result<FrameRing, GpuError> {
        if frames_in_flight == 0 {
            return Err(GpuError::InvalidArgument(
                "a frame ring needs at least one frame in flight".into(),
            ));
        }
        Ok(FrameRing {
            ctx: Arc::clone(ctx),
            slots: vec![0; frames_in_flight],
            frame: 0,
        })
    }

    /// Frames in flight.
    pub fn frames_in_flight(&self) -> usize {
        self.slots.len()
    }

    /// Frames begun so far.
    pub fn frame_number(&self) -> u64 {
        self.frame
    }

    /// Starts the next frame: waits until the GPU has finished the last submission made for this
    /// frame's slot (N frames ago), releases what it held, and returns the slot index.
    pub fn begin_frame(&mut self) -> Result<usize, GpuError> {
        let slot = (self.frame % self.slots.len() as u64) as usize;
        self.ctx.wait_for(self.slots[slot])?;
        self.frame += 1;
        Ok(slot)
    }

    /// Records `submission` as the current frame's (the slot returned by the last
    /// [`FrameRing::begin_frame`]); a frame with several submissions passes the last one.
    pub fn end_frame(&mut self, submission: &Submission) {
        if self.frame == 0 {
            return;
        }
        let slot = ((self.frame - 1) % self.slots.len() as u64) as usize;
        self.slots[slot] = self.slots[slot].max(submission.value());
    }

    /// Waits for every frame in flight.
    pub fn wait_all(&self) -> Result<(), GpuError> {
        let last = self.slots.iter().copied().max().unwrap_or(0);
        self.ctx.wait_for(last)
    }
}
