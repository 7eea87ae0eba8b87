//! The paper's quality metrics measured on a second thread, so that on a
//! multi-core machine they overlap the stabilizer instead of adding to it
//! (at 720p they cost about as much as stabilizing).
//!
//! Output frames are copied into recycled buffers and handed over through a
//! channel of [`QUEUE`] slots; the worker keeps its own [`MetricsAccumulator`].

use amc_core::metrics::{ClipMetrics, FrameMetrics, MetricsAccumulator};
use amc_core::{Frame, FrameRef, Telemetry};
use std::sync::mpsc::{channel, sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

/// Frames that may wait for the worker (bounds memory; the stabilizer
/// waits when the worker is this far behind).
const QUEUE: usize = 2;

struct Job {
    frame: Frame,
    coverage: Vec<u8>,
    telemetry: Telemetry,
}

pub struct MetricsWorker {
    jobs: Option<SyncSender<Job>>,
    spare: Receiver<Job>,
    handle: Option<JoinHandle<(ClipMetrics, Vec<FrameMetrics>)>>,
}

impl MetricsWorker {
    /// Starts the worker; with `keep_per_frame` it also returns every frame's metrics.
    pub fn start(keep_per_frame: bool) -> Self {
        let (jobs_tx, jobs_rx) = sync_channel::<Job>(QUEUE);
        let (spare_tx, spare) = channel::<Job>();
        let handle = std::thread::Builder::new()
            .name("amc-metrics".into())
            .spawn(move || {
                let mut acc = MetricsAccumulator::new();
                let mut per_frame = Vec::new();
                for job in jobs_rx {
                    let m = acc.push(
                        &job.frame.as_ref(),
                        &job.coverage,
                        job.telemetry.valid_fraction,
                        Some(&job.telemetry),
                    );
                    if keep_per_frame {
                        per_frame.push(m);
                    }
                    // The buffers go back for reuse; the sender may be gone.
                    let _ = spare_tx.send(job);
                }
                (acc.summary(), per_frame)
            })
            .ok();
        Self {
            jobs: Some(jobs_tx),
            spare,
            handle,
        }
    }

    /// Queues one output frame (copied) with its coverage and telemetry.
    pub fn push(&mut self, frame: &FrameRef<'_>, coverage: &[u8], telemetry: &Telemetry) {
        let Some(jobs) = &self.jobs else { return };
        let mut job = self.spare.try_recv().unwrap_or_else(|_| Job {
            frame: Frame::new(0, 0, frame.format),
            coverage: Vec::new(),
            telemetry: Telemetry::default(),
        });
        job.frame.copy_from(frame);
        job.coverage.clear();
        job.coverage.extend_from_slice(coverage);
        job.telemetry = telemetry.clone();
        if jobs.send(job).is_err() {
            // The worker died; `finish` reports it.
            self.jobs = None;
        }
    }

    /// Waits for the worker: the clip's metrics and (if kept) every frame's,
    /// or `None` if the worker failed.
    pub fn finish(mut self) -> Option<(ClipMetrics, Vec<FrameMetrics>)> {
        self.jobs = None;
        self.handle.take()?.join().ok()
    }
}
