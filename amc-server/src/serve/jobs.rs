//! Batch jobs: `POST /jobs` queues a clip and answers 202 at once;
//! `GET /jobs/{id}` reports state and progress; the output and telemetry
//! are fetched when done; `DELETE /jobs/{id}` cancels or removes.
//!
//! A job's files live in its own [`Scratch`] folder, dropped (with its disk
//! budget) when the job is cancelled, removed or expires. Ids are 128 random
//! bits in hex; anything else is an unknown job, so an id never names a path.

use super::intake::{self, Intake};
use super::options::OutputFormat;
use super::problem::ApiError;
use super::storage::Scratch;
use super::work::{self, WorkSpec};
use super::AppState;
use crate::engine::{RunControl, RunSummary};
use axum::body::Body;
use axum::extract::{Path as UrlPath, Request, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Serialize;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use tokio::sync::{watch, Notify};

/// Longest a `DELETE` waits for a running job to unwind (kill ffmpeg, remove files).
const CANCEL_WAIT: Duration = Duration::from_secs(15);

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

    fn finished(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled
        )
    }
}

struct JobInner {
    state: JobState,
    scratch: Option<Scratch>,
    summary: Option<RunSummary>,
    error: Option<String>,
    finished_at: Option<Instant>,
}

pub struct Job {
    id: String,
    format: OutputFormat,
    frames_total: Option<u64>,
    control: Arc<RunControl>,
    /// Wakes a queued job's task when it is cancelled.
    cancel: Notify,
    /// Becomes true when the job's task has finished with its files.
    settled: watch::Sender<bool>,
    inner: Mutex<JobInner>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// A job as `GET /jobs/{id}` shows it.
#[derive(Serialize)]
pub struct JobView {
    pub id: String,
    pub state: JobState,
    pub frames_done: u64,
    pub frames_total: Option<u64>,
    /// `frames_done / frames_total` in [0, 1], when the total is known.
    pub progress: Option<f64>,
    pub format: &'static str,
    pub error: Option<String>,
    pub metrics: Option<RunSummary>,
    pub output: Option<String>,
    pub telemetry: Option<String>,
}

impl Job {
    pub fn state(&self) -> JobState {
        lock(&self.inner).state
    }

    fn view(&self) -> JobView {
        let inner = lock(&self.inner);
        let frames_done = self.control.frames_done();
        let done = inner.state == JobState::Done;
        JobView {
            id: self.id.clone(),
            state: inner.state,
            frames_done,
            frames_total: self.frames_total,
            progress: match (done, self.frames_total) {
                (true, _) => Some(1.0),
                (false, Some(n)) if n > 0 => Some((frames_done as f64 / n as f64).min(1.0)),
                _ => None,
            },
            format: self.format.extension(),
            error: inner.error.clone(),
            metrics: inner.summary.clone(),
            output: done.then(|| format!("/jobs/{}/output", self.id)),
            telemetry: done.then(|| format!("/jobs/{}/telemetry.csv", self.id)),
        }
    }

    fn finish(&self, state: JobState, summary: Option<RunSummary>, error: Option<String>) {
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
    fn cancel(&self) -> bool {
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

    fn insert(&self, job: Arc<Job>) {
        lock(&self.jobs).insert(job.id.clone(), job);
    }

    fn remove(&self, id: &str) -> Option<Arc<Job>> {
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

fn new_id() -> String {
    use rand::RngCore;
    let mut bytes = [0u8; 16];
    rand::rngs::OsRng.fill_bytes(&mut bytes);
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// `POST /jobs`.
pub async fn create(State(state): State<Arc<AppState>>, request: Request) -> Response {
    match create_job(&state, request).await {
        Ok(view) => {
            let location = format!("/jobs/{}", view.id);
            let mut res = (StatusCode::ACCEPTED, Json(view)).into_response();
            if let Ok(v) = HeaderValue::from_str(&location) {
                res.headers_mut().insert(header::LOCATION, v);
            }
            res
        }
        Err(e) => state.refuse(e),
    }
}

async fn create_job(state: &Arc<AppState>, request: Request) -> Result<JobView, ApiError> {
    let Intake {
        admission,
        options,
        scratch,
        upload,
        inspection,
    } = intake::accept(state, request).await?;
    let id = new_id();
    let format = options.format;
    let bytes = upload.bytes;
    let spec = WorkSpec::for_upload(&scratch, upload, options, &inspection, true);
    let control = work::control(state);
    let job = Arc::new(Job {
        id: id.clone(),
        format,
        frames_total: inspection.info.frame_count,
        control,
        cancel: Notify::new(),
        settled: watch::channel(false).0,
        inner: Mutex::new(JobInner {
            state: JobState::Queued,
            scratch: Some(scratch),
            summary: None,
            error: None,
            finished_at: None,
        }),
    });
    state.jobs.insert(job.clone());
    tracing::info!(job = %id, bytes, frames = ?job.frames_total, "job queued");
    let view = job.view();
    let task_state = state.clone();
    state.tasks.spawn(async move {
        run(task_state, job, spec).await;
        drop(admission);
    });
    Ok(view)
}

/// A job's life after its upload: wait for a worker, stabilize, settle.
async fn run(state: Arc<AppState>, job: Arc<Job>, spec: WorkSpec) {
    let permit = tokio::select! {
        p = state.cpu.clone().acquire_owned() => p.ok(),
        _ = job.cancel.notified() => None,
    };
    let Some(permit) = permit else {
        job.finish(JobState::Cancelled, None, None);
        return;
    };
    {
        let mut inner = lock(&job.inner);
        if inner.state != JobState::Queued {
            drop(inner);
            job.finish(JobState::Cancelled, None, None);
            return;
        }
        inner.state = JobState::Running;
    }
    tracing::info!(job = %job.id, "job running");
    let limits = state.limits.clone();
    let control = job.control.clone();
    let worker = state
        .tasks
        .spawn_blocking(move || {
            let result = work::stabilize(&spec, &limits, &control);
            (spec, result)
        })
        .await;
    drop(permit);
    match worker {
        Ok((spec, Ok(summary))) => {
            {
                let inner = lock(&job.inner);
                if let Some(scratch) = &inner.scratch {
                    scratch.remove(&spec.input);
                    scratch.account(&spec.output);
                    if let Some(t) = &spec.telemetry {
                        scratch.account(t);
                    }
                }
            }
            tracing::info!(job = %job.id, frames = summary.frames, fps = summary.frames_per_second, "job done");
            job.finish(JobState::Done, Some(summary), None);
        }
        Ok((_, Err(e))) => {
            if job.control.is_cancelled() {
                tracing::info!(job = %job.id, "job cancelled");
                job.finish(JobState::Cancelled, None, None);
            } else {
                tracing::warn!(job = %job.id, error = %e, "job failed");
                job.finish(JobState::Failed, None, Some(e.to_string()));
            }
        }
        Err(e) => {
            tracing::error!(job = %job.id, error = %e, "job worker panicked");
            job.finish(
                JobState::Failed,
                None,
                Some("internal error while processing; the clip was not stabilized".into()),
            );
        }
    }
}

/// `GET /jobs/{id}`.
pub async fn get(
    State(state): State<Arc<AppState>>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<JobView>, ApiError> {
    Ok(Json(state.jobs.get(&id)?.view()))
}

/// Streams one of a finished job's files.
async fn file_of(
    state: &AppState,
    id: &str,
    name: impl Fn(&Job) -> (String, &'static str, String),
) -> Result<Response, ApiError> {
    let job = state.jobs.get(id)?;
    let (file, content_type, download) = name(&job);
    let path = {
        let inner = lock(&job.inner);
        if inner.state != JobState::Done {
            return Err(ApiError::Conflict(format!(
                "job {id} is {}; its files exist once it is done",
                inner.state.name()
            )));
        }
        match &inner.scratch {
            Some(s) => s.file(&file),
            None => return Err(ApiError::JobNotFound(id.to_string())),
        }
    };
    // Opened before answering: the file stays readable even if the job
    // expires or is deleted while it streams.
    let f = tokio::fs::File::open(&path)
        .await
        .map_err(|_| ApiError::JobNotFound(id.to_string()))?;
    let len = f.metadata().await.map(|m| m.len()).ok();
    let mut res = Response::new(Body::from_stream(tokio_util::io::ReaderStream::new(f)));
    let h = res.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    if let Some(len) = len {
        h.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
    }
    if let Ok(v) = HeaderValue::from_str(&format!("attachment; filename=\"{download}\"")) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    Ok(res)
}

/// `GET /jobs/{id}/output`.
pub async fn output(
    State(state): State<Arc<AppState>>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ApiError> {
    file_of(&state, &id, |job| {
        let ext = job.format.extension();
        (
            format!("output.{ext}"),
            job.format.content_type(),
            format!("stabilized-{}.{ext}", &job.id[..8]),
        )
    })
    .await
}

/// `GET /jobs/{id}/telemetry.csv`.
pub async fn telemetry(
    State(state): State<Arc<AppState>>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ApiError> {
    file_of(&state, &id, |job| {
        (
            "telemetry.csv".into(),
            "text/csv",
            format!("telemetry-{}.csv", &job.id[..8]),
        )
    })
    .await
}

/// `DELETE /jobs/{id}`: cancels a queued or running job (200 with its state,
/// once its ffmpeg children are gone and its files removed), or removes a
/// finished one and its files (204).
pub async fn delete(
    State(state): State<Arc<AppState>>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ApiError> {
    let job = state.jobs.get(&id)?;
    if job.cancel() {
        let mut settled = job.settled.subscribe();
        let _ = tokio::time::timeout(CANCEL_WAIT, settled.wait_for(|s| *s)).await;
        tracing::info!(job = %id, "job cancelled by request");
        return Ok(Json(job.view()).into_response());
    }
    state.jobs.remove(&id);
    Ok(StatusCode::NO_CONTENT.into_response())
}
