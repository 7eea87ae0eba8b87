//! The job table: each [`Job`]'s state, files and result, what `GET /jobs`
//! and `GET /jobs/{id}` show of it, counting and expiry.
//!
//! A job's files live in its own [`Scratch`] folder, dropped (with its disk
//! budget) when the job is cancelled, removed or expires. Ids are 128 random
//! bits in hex; anything else is an unknown job, so an id never names a path.

use super::view::{progress, rfc3339, valid_id, JobPage, JobState, JobSummary, JobView};
use super::view::{JobMetrics, JobMotion};
use crate::serve::options::OutputFormat;
use crate::serve::problem::ApiError;
use crate::serve::storage::Scratch;
use amc_engine::{RunControl, RunSummary};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};
use tokio::sync::{watch, Notify};

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
    /// The tenant whose key submitted it: only it (and `admin`) sees it.
    pub tenant: String,
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

pub use crate::poison::lock;

impl Job {
    pub fn state(&self) -> JobState {
        lock(&self.inner).state
    }

    /// A new queued job.
    pub fn new(
        id: String,
        tenant: String,
        format: OutputFormat,
        frames_total: Option<u64>,
        control: Arc<RunControl>,
        scratch: Scratch,
    ) -> Self {
        static SEQ: AtomicU64 = AtomicU64::new(0);
        Self {
            id,
            tenant,
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
        progress(state, frames_done, self.frames_total)
    }

    pub fn view(&self) -> JobView {
        let inner = lock(&self.inner);
        let done = inner.state == JobState::Done;
        JobView {
            summary: self.summary_in(inner.state),
            format: self.format.extension(),
            error: inner.error.clone(),
            metrics: inner.summary.as_ref().map(JobMetrics::of),
            motion: inner.summary.as_ref().map(JobMotion::of),
            output: done.then(|| format!("/jobs/{}/output", self.id)),
            telemetry: done.then(|| format!("/jobs/{}/telemetry.csv", self.id)),
        }
    }

    fn summary(&self) -> JobSummary {
        self.summary_in(self.state())
    }

    /// The job's summary while it is in `state`.
    fn summary_in(&self, state: JobState) -> JobSummary {
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
    /// A job by id, if `tenant` may see it (`None`: every tenant's, for
    /// `admin`): another tenant's job is unknown, exactly as a missing one.
    /// Ids that are not 32 hex digits are never looked up.
    pub fn get(&self, id: &str, tenant: Option<&str>) -> Result<Arc<Job>, ApiError> {
        let valid = valid_id(id);
        let unknown = || ApiError::JobNotFound(id.chars().take(64).collect());
        if !valid {
            return Err(unknown());
        }
        lock(&self.jobs)
            .get(id)
            .filter(|j| tenant.is_none_or(|t| j.tenant == t))
            .cloned()
            .ok_or_else(unknown)
    }

    pub fn insert(&self, job: Arc<Job>) {
        lock(&self.jobs).insert(job.id.clone(), job);
    }

    /// Up to `limit` jobs of `tenant` (`None`: every tenant's) accepted
    /// before `before` (a cursor; `None`: the newest), newest first.
    pub fn page(&self, tenant: Option<&str>, limit: usize, before: Option<u64>) -> JobPage {
        let mut jobs: Vec<Arc<Job>> = lock(&self.jobs)
            .values()
            .filter(|j| before.is_none_or(|b| j.seq < b))
            .filter(|j| tenant.is_none_or(|t| j.tenant == t))
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
                if i == 2 { "other" } else { "local" }.to_string(),
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
            let page = store.page(None, 2, cursor);
            assert!(page.jobs.len() <= 2);
            seen.extend(page.jobs.iter().map(|j| j.id.clone()));
            match page.next_cursor {
                Some(c) => cursor = Some(c.parse().unwrap()),
                None => break,
            }
        }
        assert_eq!(seen, ids);
        let local = store.page(Some("local"), 100, None);
        assert_eq!(local.jobs.len(), 4, "another tenant's job is not listed");
        assert!(local.jobs.iter().all(|j| j.id != ids[2]));
        assert!(store.get(&ids[2], Some("local")).is_err());
        assert!(store.get(&ids[2], Some("other")).is_ok());
        assert!(store.get(&ids[2], None).is_ok());
        let first = store.page(None, 100, None);
        assert_eq!(first.jobs.len(), 5);
        assert!(first.next_cursor.is_none());
        assert_eq!(first.jobs[0].state, JobState::Queued);
        assert_eq!(first.jobs[0].progress, Some(0.0));
    }
}
