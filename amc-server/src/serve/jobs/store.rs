//! The job table: each [`Job`]'s state, files and result, what `GET /jobs`
//! and `GET /jobs/{id}` show of it, counting and expiry.
//!
//! A job's files live in its own [`Scratch`] folder, dropped (with its disk
//! budget) when the job is cancelled, removed or expires. Ids are 128 random
//! bits in hex; anything else is an unknown job, so an id never names a path.

use crate::engine::{RunControl, RunSummary};
use crate::serve::options::OutputFormat;
use crate::serve::problem::ApiError;
use crate::serve::storage::Scratch;
use serde::Serialize;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant, SystemTime};
use tokio::sync::{watch, Notify};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum JobState {
    Queued,
    Running,
    Done,
    Failed,
    Cancelled,
}

impl JobState {
    pub const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Done,
        JobState::Failed,
        JobState::Cancelled,
    ];

    pub fn name(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    pub fn finished(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled
        )
    }
}

/// What changes in a job's life.
pub struct JobInner {
    pub state: JobState,
    pub scratch: Option<Scratch>,
    pub summary: Option<RunSummary>,
    pub error: Option<String>,
    pub finished_at: Option<Instant>,
}

/// One job.
pub struct Job {
    pub id: String,
    pub format: OutputFormat,
    pub frames_total: Option<u64>,
    pub control: Arc<RunControl>,
    /// Wakes a queued job's task when it is cancelled.
    pub cancel: Notify,
    /// Becomes true when the job's task has finished with its files.
    pub settled: watch::Sender<bool>,
    /// When it was accepted (wall clock, shown) ...
    created: SystemTime,
    /// ... and its place in the order of acceptance (listing, cursors).
    seq: u64,
    pub inner: Mutex<JobInner>,
}

pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A job as `GET /jobs/{id}` shows it.
#[derive(Serialize)]
pub struct JobView {
    pub id: String,
    pub state: JobState,
    /// When the job was accepted, RFC 3339 UTC.
    pub created: String,
    pub frames_done: u64,
    pub frames_total: Option<u64>,
    /// `frames_done / frames_total` in [0, 1], when the total is known.
    pub progress: Option<f64>,
    pub format: &'static str,
    pub error: Option<String>,
    /// The clip's measurements, when done.
    pub metrics: Option<JobMetrics>,
    /// The camera's and the view's motion, when done.
    pub motion: Option<JobMotion>,
    pub output: Option<String>,
    pub telemetry: Option<String>,
}

/// What a finished job measured: one flat object, each value once.
#[derive(Serialize)]
pub struct JobMetrics {
    /// Output frames.
    pub frames: u64,
    pub input_size: (usize, usize),
    pub output_size: (usize, usize),
    /// Processing time and rate.
    pub seconds: f64,
    pub frames_per_second: f64,
    /// The paper's image metrics of the output; null with `metrics=false`.
    pub rms_normal_flow: Option<f64>,
    pub rms_frame_change: Option<f64>,
    pub sharpness: Option<f64>,
    /// Share of pixels covered by every averaged frame: mean and lowest.
    pub valid_fraction: f64,
    pub min_valid_fraction: f64,
}

/// The motion a finished job's telemetry shows.
#[derive(Serialize)]
pub struct JobMotion {
    /// RMS angular speed of the camera (estimated) and of the view, deg/s.
    pub rms_speed_est_dps: f64,
    pub rms_speed_view_dps: f64,
    /// Saccades made (saccade mode).
    pub saccades: u64,
}

impl JobMetrics {
    fn of(s: &RunSummary) -> Self {
        let image = s.metrics.as_ref();
        Self {
            frames: s.frames,
            input_size: s.input_size,
            output_size: s.output_size,
            seconds: s.seconds,
            frames_per_second: s.frames_per_second,
            rms_normal_flow: image.map(|m| m.rms_normal_flow),
            rms_frame_change: image.map(|m| m.rms_change),
            sharpness: image.map(|m| m.sharpness),
            valid_fraction: s.motion.valid_fraction,
            min_valid_fraction: s.motion.min_valid_fraction,
        }
    }
}

impl JobMotion {
    fn of(s: &RunSummary) -> Self {
        Self {
            rms_speed_est_dps: s.motion.rms_speed_est_dps,
            rms_speed_view_dps: s.motion.rms_speed_view_dps,
            saccades: s.motion.saccades,
        }
    }
}

/// A job as `GET /jobs` lists it.
#[derive(Serialize)]
pub struct JobSummary {
    pub id: String,
    pub state: JobState,
    pub created: String,
    pub frames_done: u64,
    pub frames_total: Option<u64>,
    pub progress: Option<f64>,
}

/// One page of `GET /jobs`, newest first.
#[derive(Serialize)]
pub struct JobPage {
    pub jobs: Vec<JobSummary>,
    /// Pass as `cursor` for the next (older) page; null on the last page.
    pub next_cursor: Option<String>,
}

/// Seconds since the Unix epoch as RFC 3339 UTC (`2026-11-29T21:04:05Z`).
pub fn rfc3339(t: SystemTime) -> String {
    let secs = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

impl Job {
    pub fn state(&self) -> JobState {
        lock(&self.inner).state
    }

    /// A new queued job.
    pub fn new(
        id: String,
        format: OutputFormat,
        frames_total: Option<u64>,
        control: Arc<RunControl>,
        scratch: Scratch,
    ) -> Self {
        static SEQ: AtomicU64 = AtomicU64::new(0);
        Self {
            id,
            format,
            frames_total,
            control,
            cancel: Notify::new(),
            settled: watch::channel(false).0,
            created: SystemTime::now(),
            seq: SEQ.fetch_add(1, Ordering::SeqCst) + 1,
            inner: Mutex::new(JobInner {
                state: JobState::Queued,
                scratch: Some(scratch),
                summary: None,
                error: None,
                finished_at: None,
            }),
        }
    }

    fn progress(&self, state: JobState, frames_done: u64) -> Option<f64> {
        match (state == JobState::Done, self.frames_total) {
            (true, _) => Some(1.0),
            (false, Some(n)) if n > 0 => Some((frames_done as f64 / n as f64).min(1.0)),
            _ => None,
        }
    }

    pub fn view(&self) -> JobView {
        let inner = lock(&self.inner);
        let frames_done = self.control.frames_done();
        let done = inner.state == JobState::Done;
        JobView {
            id: self.id.clone(),
            state: inner.state,
            created: rfc3339(self.created),
            frames_done,
            frames_total: self.frames_total,
            progress: self.progress(inner.state, frames_done),
            format: self.format.extension(),
            error: inner.error.clone(),
            metrics: inner.summary.as_ref().map(JobMetrics::of),
            motion: inner.summary.as_ref().map(JobMotion::of),
            output: done.then(|| format!("/jobs/{}/output", self.id)),
            telemetry: done.then(|| format!("/jobs/{}/telemetry.csv", self.id)),
        }
    }

    fn summary(&self) -> JobSummary {
        let state = self.state();
        let frames_done = self.control.frames_done();
        JobSummary {
            id: self.id.clone(),
            state,
            created: rfc3339(self.created),
            frames_done,
            frames_total: self.frames_total,
            progress: self.progress(state, frames_done),
        }
    }

    pub fn finish(&self, state: JobState, summary: Option<RunSummary>, error: Option<String>) {
        let mut inner = lock(&self.inner);
        if inner.state == JobState::Cancelled {
            // Cancelled while running: the work's result does not matter.
            inner.scratch = None;
        } else {
            inner.state = state;
            inner.summary = summary;
            inner.error = error;
            if state != JobState::Done {
                inner.scratch = None;
            }
        }
        inner.finished_at = Some(Instant::now());
        drop(inner);
        self.settled.send_replace(true);
    }

    /// Cancels a queued or running job; false if it had already finished.
    pub fn cancel(&self) -> bool {
        let mut inner = lock(&self.inner);
        if inner.state.finished() {
            return false;
        }
        inner.state = JobState::Cancelled;
        inner.finished_at = Some(Instant::now());
        drop(inner);
        self.control.cancel();
        self.cancel.notify_one();
        true
    }
}

/// All jobs the service knows.
#[derive(Default)]
pub struct JobStore {
    jobs: Mutex<HashMap<String, Arc<Job>>>,
}

impl JobStore {
    /// A job by id; ids that are not 32 hex digits are never looked up.
    pub fn get(&self, id: &str) -> Result<Arc<Job>, ApiError> {
        let valid = id.len() == 32 && id.bytes().all(|b| b.is_ascii_hexdigit());
        let unknown = || ApiError::JobNotFound(id.chars().take(64).collect());
        if !valid {
            return Err(unknown());
        }
        lock(&self.jobs).get(id).cloned().ok_or_else(unknown)
    }

    pub fn insert(&self, job: Arc<Job>) {
        lock(&self.jobs).insert(job.id.clone(), job);
    }

    /// Up to `limit` jobs accepted before `before` (a cursor; `None`: the
    /// newest), newest first.
    pub fn page(&self, limit: usize, before: Option<u64>) -> JobPage {
        let mut jobs: Vec<Arc<Job>> = lock(&self.jobs)
            .values()
            .filter(|j| before.is_none_or(|b| j.seq < b))
            .cloned()
            .collect();
        jobs.sort_by_key(|j| std::cmp::Reverse(j.seq));
        let more = jobs.len() > limit;
        jobs.truncate(limit);
        JobPage {
            next_cursor: more
                .then(|| jobs.last().map(|j| j.seq.to_string()))
                .flatten(),
            jobs: jobs.iter().map(|j| j.summary()).collect(),
        }
    }

    pub fn remove(&self, id: &str) -> Option<Arc<Job>> {
        lock(&self.jobs).remove(id)
    }

    /// Number of jobs in each state.
    pub fn counts(&self) -> HashMap<JobState, usize> {
        let mut counts = HashMap::new();
        for job in lock(&self.jobs).values() {
            *counts.entry(job.state()).or_insert(0) += 1;
        }
        counts
    }

    /// Removes finished jobs older than `ttl` (and their files).
    pub fn expire(&self, ttl: Duration) -> usize {
        let now = Instant::now();
        let mut jobs = lock(&self.jobs);
        let before = jobs.len();
        jobs.retain(|_, job| {
            let inner = lock(&job.inner);
            !(inner.state.finished()
                && inner
                    .finished_at
                    .is_some_and(|t| now.duration_since(t) > ttl))
        });
        before - jobs.len()
    }

    /// Cancels every job (shutdown).
    pub fn cancel_all(&self) {
        for job in lock(&self.jobs).values() {
            job.cancel();
        }
    }

    /// Drops every job and its files (shutdown, after the tasks have ended).
    pub fn clear(&self) {
        lock(&self.jobs).clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::storage::DiskBudget;

    #[test]
    fn pages_list_every_job_once_newest_first() {
        let dir = tempfile::tempdir().unwrap();
        let budget = Arc::new(DiskBudget::new(1 << 20));
        let store = JobStore::default();
        let mut ids = Vec::new();
        for i in 0..5 {
            let id = format!("{i:032x}");
            let scratch = Scratch::new(dir.path(), budget.clone()).unwrap();
            let control = Arc::new(RunControl::new(None));
            store.insert(Arc::new(Job::new(
                id.clone(),
                OutputFormat::Mp4,
                Some(10),
                control,
                scratch,
            )));
            ids.push(id);
        }
        ids.reverse();
        let mut seen = Vec::new();
        let mut cursor = None;
        loop {
            let page = store.page(2, cursor);
            assert!(page.jobs.len() <= 2);
            seen.extend(page.jobs.iter().map(|j| j.id.clone()));
            match page.next_cursor {
                Some(c) => cursor = Some(c.parse().unwrap()),
                None => break,
            }
        }
        assert_eq!(seen, ids);
        let first = store.page(100, None);
        assert_eq!(first.jobs.len(), 5);
        assert!(first.next_cursor.is_none());
        assert_eq!(first.jobs[0].state, JobState::Queued);
        assert_eq!(first.jobs[0].progress, Some(0.0));
    }
}
