//! One claimed job, start to end: download, run (renewing the lease and
//! writing progress), upload, record the outcome, clean up.
//!
//! Who decides what happens to the job:
//! - the run failed because of the clip or its options: failed, with the
//!   reason (a retry would fail the same way);
//! - the worker is stopping, or the bucket is down so the input cannot be
//!   read or the output cannot be written: handed back to the queue, not
//!   counted as an attempt (the job is not at fault);
//! - the renewal found the row no longer ours (cancelled by `DELETE`, or
//!   presumed dead and claimed by another worker): the run is stopped and
//!   nothing is written; objects this claim uploaded are removed.

use super::state::WorkerState;
use crate::cluster::queue::{Claim, Outcome};
use crate::serve::jobs::{JobFile, JobMetrics, JobMotion};
use crate::serve::options::JobOptions;
use crate::serve::panics::PANICKED;
use crate::serve::work::{self, WorkSpec};
use amc_engine::{RunControl, RunSummary};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::sync::watch;

/// How often the lease is renewed and progress written; also how quickly a
/// cancellation reaches the run.
const HEARTBEAT: Duration = Duration::from_millis(500);

/// How a run ended, as far as the job table is concerned.
enum Ending {
    Done {
        summary: Box<RunSummary>,
        output_key: String,
        telemetry_key: String,
    },
    /// The clip's or the options' fault: the reason.
    Failed(String),
    /// Not the job's fault: back to the queue.
    HandBack(String),
    /// The row is no longer this claim's.
    Lost,
}

/// Runs `claim` to its end. True when the job was handed back because
/// something it needs is down (the caller pauses before claiming again).
pub(super) async fn run(
    state: &Arc<WorkerState>,
    claim: Claim,
    stop: &mut watch::Receiver<bool>,
) -> bool {
    let started = Instant::now();
    state.busy.store(true, Ordering::SeqCst);
    if claim.attempt > 1 {
        tracing::warn!(job = %claim.id, attempt = claim.attempt, "retrying a job whose worker stopped answering");
    }
    tracing::info!(job = %claim.id, attempt = claim.attempt, worker = %state.name, "job running");
    let ending = match super::scratch::create(&state.work_dir, &state.host) {
        Ok(scratch) => {
            let ending = run_in(state, &claim, scratch.path(), stop).await;
            drop(scratch);
            ending
        }
        Err(e) => Ending::HandBack(format!(
            "cannot make a scratch folder in {}: {e}",
            state.work_dir.display()
        )),
    };
    let outcome = record(state, &claim, ending).await;
    state
        .metrics
        .job_finished(outcome, started.elapsed().as_secs_f64());
    state.busy.store(false, Ordering::SeqCst);
    outcome == "handed_back" && !*stop.borrow()
}

/// Downloads, runs and uploads in `scratch`.
async fn run_in(
    state: &Arc<WorkerState>,
    claim: &Claim,
    scratch: &std::path::Path,
    stop: &mut watch::Receiver<bool>,
) -> Ending {
    let store = &state.cluster.store;
    let input = scratch.join("input");
    match store.download(&claim.input_key, &input).await {
        Ok(_) => {}
        Err(e) if e.not_found() => {
            return Ending::Failed("the upload is no longer in the store".into())
        }
        Err(e) => return Ending::HandBack(format!("cannot download the upload: {e}")),
    }
    // The client's gyro log, named as the replica stored it: its extension
    // tells telemetry-parser some formats.
    let gyro_log = match &claim.gyro_key {
        Some(key) => {
            let name = key.rsplit('/').next().unwrap_or("gyro");
            let path = scratch.join(format!(
                "gyro-log{}",
                name.strip_prefix("gyro").unwrap_or("")
            ));
            match store.download(key, &path).await {
                Ok(_) => Some(path),
                Err(e) if e.not_found() => {
                    return Ending::Failed("the gyro log is no longer in the store".into())
                }
                Err(e) => return Ending::HandBack(format!("cannot download the gyro log: {e}")),
            }
        }
        None => None,
    };
    let options = match JobOptions::from_query(Some(&claim.options)) {
        Ok(o) => o,
        Err(e) => return Ending::Failed(e.to_string()),
    };
    let extension = options.format.extension();
    let telemetry = scratch.join(JobFile::Telemetry.name(options.format));
    let spec = WorkSpec {
        input,
        output: scratch.join(JobFile::Output.name(options.format)),
        telemetry: Some(telemetry.clone()),
        lens_text: claim.lens.clone(),
        gyro_log,
        options,
        input_size: (claim.width.max(0) as usize, claim.height.max(0) as usize),
    };
    let control = Arc::new(
        RunControl::new(Some(state.limits.job_time_limit))
            .counting_into(state.metrics.frames_processed.clone()),
    );
    let lost = Arc::new(AtomicBool::new(false));
    let heartbeat = tokio::spawn(heartbeat(
        state.clone(),
        claim.clone(),
        control.clone(),
        lost.clone(),
    ));
    let limits = state.limits.clone();
    let run_control = control.clone();
    let mut blocking = tokio::task::spawn_blocking(move || {
        let result = work::stabilize(&spec, &limits, &run_control);
        (spec, result)
    });
    let mut stopping = false;
    let joined = tokio::select! {
        r = &mut blocking => r,
        _ = stop.wait_for(|s| *s) => {
            stopping = true;
            control.cancel();
            // The run unwinds: its ffmpeg children are killed, its files removed.
            (&mut blocking).await
        }
    };
    heartbeat.abort();
    if stopping {
        return Ending::HandBack("the worker is stopping".into());
    }
    if lost.load(Ordering::SeqCst) {
        return Ending::Lost;
    }
    let (spec, result) = match joined {
        Ok(done) => done,
        Err(e) => {
            tracing::error!(job = %claim.id, error = %e, "job run panicked");
            return Ending::Failed(PANICKED.into());
        }
    };
    let summary = match result {
        Ok(s) => s,
        Err(e) => return Ending::Failed(e.to_string()),
    };
    let output_key = store.output_key(&claim.tenant, &claim.id, claim.attempt, extension);
    let telemetry_key = store.telemetry_key(&claim.tenant, &claim.id, claim.attempt);
    for (key, path) in [(&output_key, &spec.output), (&telemetry_key, &telemetry)] {
        if let Err(e) = store.put_file(key, path).await {
            let _ = store.delete(&output_key).await;
            return Ending::HandBack(format!("cannot upload the result: {e}"));
        }
    }
    Ending::Done {
        summary: Box::new(summary),
        output_key,
        telemetry_key,
    }
}

/// Renews the lease and writes progress until aborted; cancels the run when
/// the row is no longer this claim's.
async fn heartbeat(
    state: Arc<WorkerState>,
    claim: Claim,
    control: Arc<RunControl>,
    lost: Arc<AtomicBool>,
) {
    let lease = state.cluster.config.lease;
    let mut tick = tokio::time::interval(HEARTBEAT);
    loop {
        tick.tick().await;
        match state
            .cluster
            .queue
            .heartbeat(&claim, &state.name, control.frames_done(), lease)
            .await
        {
            Ok(true) => {}
            Ok(false) => {
                tracing::info!(job = %claim.id, "job cancelled or taken over; stopping its run");
                lost.store(true, Ordering::SeqCst);
                control.cancel();
                return;
            }
            // The run goes on; if the database stays away past the lease,
            // another worker may take the job, and this claim's result is
            // then not recorded.
            Err(e) => tracing::warn!(job = %claim.id, error = %e, "cannot renew the lease now"),
        }
    }
}

/// Writes the ending into the job table; the outcome's name for `/metrics`.
async fn record(state: &Arc<WorkerState>, claim: &Claim, ending: Ending) -> &'static str {
    let queue = &state.cluster.queue;
    let store = &state.cluster.store;
    let id = &claim.id;
    match ending {
        Ending::Done {
            summary,
            output_key,
            telemetry_key,
        } => {
            let metrics = serde_json::to_string(&JobMetrics::of(&summary)).unwrap_or_default();
            let motion = serde_json::to_string(&JobMotion::of(&summary)).unwrap_or_default();
            let outcome = Outcome::Done {
                output_key: &output_key,
                telemetry_key: &telemetry_key,
                frames: summary.frames as i64,
                metrics: &metrics,
                motion: &motion,
            };
            match queue.finish(claim, &state.name, &outcome).await {
                Ok(true) => {
                    tracing::info!(job = %id, frames = summary.frames, fps = summary.frames_per_second, "job done");
                    // The upload (and its gyro log) is no longer needed.
                    for key in std::iter::once(&claim.input_key).chain(&claim.gyro_key) {
                        if let Err(e) = store.delete(key).await {
                            tracing::warn!(job = %id, error = %e, "cannot remove a done job's upload; it goes when the job expires");
                        }
                    }
                    "done"
                }
                other => {
                    let _ = store.delete(&output_key).await;
                    let _ = store.delete(&telemetry_key).await;
                    if let Err(e) = other {
                        tracing::warn!(job = %id, error = %e, "cannot record a finished job; another worker will run it again");
                        "lost"
                    } else {
                        // Cancelled (or taken over) as the run ended: let go of
                        // the claim as a stopped run does, so that `DELETE`
                        // answers now rather than after its longest wait.
                        let _ = queue.release(claim, &state.name).await;
                        tracing::info!(job = %id, "job finished here but was cancelled or taken over; result discarded");
                        "cancelled"
                    }
                }
            }
        }
        Ending::Failed(reason) => {
            match queue
                .finish(claim, &state.name, &Outcome::Failed { error: &reason })
                .await
            {
                Ok(true) => {
                    tracing::warn!(job = %id, error = %reason, "job failed");
                    let _ = store.delete(&claim.input_key).await;
                    if let Some(key) = &claim.gyro_key {
                        let _ = store.delete(key).await;
                    }
                    "failed"
                }
                Ok(false) => {
                    // As above: the row was no longer ours.
                    let _ = queue.release(claim, &state.name).await;
                    "cancelled"
                }
                Err(e) => {
                    tracing::warn!(job = %id, error = %e, "cannot record a failed job");
                    "lost"
                }
            }
        }
        Ending::HandBack(why) => {
            match queue.hand_back(claim, &state.name).await {
                Ok(true) => {
                    tracing::info!(job = %id, reason = %why, "job handed back to the queue")
                }
                Ok(false) => {
                    let _ = queue.release(claim, &state.name).await;
                }
                Err(e) => {
                    tracing::warn!(job = %id, error = %e, reason = %why, "cannot hand the job back; it is retried when its lease runs out")
                }
            }
            "handed_back"
        }
        Ending::Lost => {
            let _ = queue.release(claim, &state.name).await;
            tracing::info!(job = %id, "job stopped: cancelled or taken over");
            "cancelled"
        }
    }
}
