//! Control of a run from another thread: cancel it, bound its time, read its progress.

use super::RunError;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Controls a run from another thread (a signal handler, the service's job table).
#[derive(Debug, Default)]
pub struct RunControl {
    cancelled: AtomicBool,
    frames_done: AtomicU64,
    /// When the run must have finished, and the limit it came from (seconds).
    deadline: Option<(Instant, f64)>,
    /// A counter shared by many runs (the service's frames processed).
    shared_frames: Option<Arc<AtomicU64>>,
}

impl RunControl {
    /// A control whose run is stopped once `limit` has passed (if any).
    pub fn new(limit: Option<Duration>) -> Self {
        Self {
            deadline: limit.map(|l| (Instant::now() + l, l.as_secs_f64())),
            ..Self::default()
        }
    }

    /// Also counts this run's frames in `counter`.
    pub fn counting_into(mut self, counter: Arc<AtomicU64>) -> Self {
        self.shared_frames = Some(counter);
        self
    }

    /// Asks the run to stop at its next frame (its children are killed, its partial output removed).
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::SeqCst);
    }

    /// Whether [`cancel`](Self::cancel) was called.
    pub fn is_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::SeqCst)
    }

    /// Output frames written so far.
    pub fn frames_done(&self) -> u64 {
        self.frames_done.load(Ordering::Relaxed)
    }

    /// Counts one output frame.
    pub(crate) fn frame_written(&self) {
        self.frames_done.fetch_add(1, Ordering::Relaxed);
        if let Some(shared) = &self.shared_frames {
            shared.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// `Err` once the run is cancelled or past its time limit.
    pub(crate) fn check(&self) -> Result<(), RunError> {
        if self.is_cancelled() {
            return Err(RunError::Cancelled);
        }
        match self.deadline {
            Some((at, secs)) if Instant::now() > at => Err(RunError::TimeLimit { secs }),
            _ => Ok(()),
        }
    }
}
