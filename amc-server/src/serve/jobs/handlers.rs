//! The job endpoints: `POST /jobs` queues a clip and answers 202 at once;
//! `GET /jobs` lists jobs; `GET /jobs/{id}` reports state and progress; the
//! output and telemetry are fetched when done; `DELETE /jobs/{id}` cancels
//! or removes. A job's task waits for a worker, stabilizes, settles.

use super::shared;
use super::store::{lock, Job};
use super::view::{JobFile, JobPage, JobState, JobView};
use crate::auth::gate::principal;
use crate::auth::{Principal, Roles};
use crate::serve::intake::{self, LocalWork};
use crate::serve::panics::PANICKED;
use crate::serve::problem::ApiError;
use crate::serve::state::AppState;
use crate::serve::work::{self, WorkSpec};
use axum::body::Body;
use axum::extract::{Extension, Path as UrlPath, Request, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use std::sync::Arc;
use std::time::Duration;

/// Longest a `DELETE` waits for a running job to unwind (kill ffmpeg, remove files).
const CANCEL_WAIT: Duration = Duration::from_secs(15);

/// Whose jobs `who` sees: its tenant's, or every tenant's for `admin`.
pub(super) fn scope(who: &Principal) -> Option<&str> {
    if who.roles.has(Roles::ADMIN) {
        None
    } else {
        Some(&who.tenant)
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
            let location = format!("/jobs/{}", view.summary.id);
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
    let who = principal(&request)?;
    if let Some(cluster) = &state.cluster {
        // The shared table counts the tenant's jobs on every replica.
        if state.auth.enabled() {
            let max = state.auth.config.max_jobs_per_tenant;
            let active = cluster.queue.active(&who.tenant).await?;
            if active >= max as i64 {
                return Err(crate::auth::too_many_jobs(&who.tenant, active as u64, max));
            }
        }
        let intake = intake::accept(state, &who, request).await?;
        return shared::create(cluster, new_id(), &who.tenant, intake).await;
    }
    let intake = intake::accept(state, &who, request).await?;
    let LocalWork {
        spec,
        control,
        bytes,
        frames,
        scratch,
        admission,
        tenant_slot,
    } = intake.into_local(state, true);
    let id = new_id();
    let job = Arc::new(Job::new(
        id.clone(),
        who.tenant.clone(),
        spec.options.format,
        frames,
        control,
        scratch,
    ));
    state.jobs.insert(job.clone());
    tracing::info!(job = %id, bytes, frames = ?job.frames_total, "job queued");
    let view = job.view();
    let task_state = state.clone();
    state.tasks.spawn(async move {
        run(task_state, job, spec).await;
        drop(admission);
        drop(tenant_slot);
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
    let started = std::time::Instant::now();
    let worker = work::stabilize_on_worker(&state, spec, job.control.clone()).await;
    drop(permit);
    let outcome = match &worker {
        Ok((_, Ok(_))) => "done",
        _ if job.control.is_cancelled() => "cancelled",
        _ => "failed",
    };
    state
        .metrics
        .job_finished(outcome, started.elapsed().as_secs_f64());
    match worker {
        Ok((spec, Ok(summary))) => {
            {
                let inner = lock(&job.inner);
                if let Some(scratch) = &inner.scratch {
                    scratch.remove(&spec.input);
                    if let Some(log) = &spec.gyro_log {
                        scratch.remove(log);
                    }
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
            job.finish(JobState::Failed, None, Some(PANICKED.into()));
        }
    }
}

/// Jobs listed per page by default, and at most.
const PAGE_DEFAULT: usize = 20;
const PAGE_MAX: usize = 100;

/// `GET /jobs?limit=N&cursor=C`: the jobs the service knows, newest first,
/// `limit` (1..=100, default 20) per page; `next_cursor` fetches the next.
pub async fn list(
    State(state): State<Arc<AppState>>,
    Extension(who): Extension<Principal>,
    uri: axum::http::Uri,
) -> Result<Json<JobPage>, ApiError> {
    let mut limit = PAGE_DEFAULT;
    let mut cursor = None;
    for (key, value) in form_urlencoded::parse(uri.query().unwrap_or("").as_bytes()) {
        match key.as_ref() {
            "limit" => {
                limit = value
                    .trim()
                    .parse::<usize>()
                    .ok()
                    .filter(|n| (1..=PAGE_MAX).contains(n))
                    .ok_or_else(|| {
                        ApiError::BadOption(format!(
                            "invalid limit: {value:?} (allowed: 1..={PAGE_MAX})"
                        ))
                    })?
            }
            "cursor" => {
                cursor = Some(value.trim().parse::<u64>().map_err(|_| {
                    ApiError::BadOption(format!(
                        "invalid cursor: {value:?} (allowed: the next_cursor of a previous page)"
                    ))
                })?)
            }
            other => {
                return Err(ApiError::BadOption(format!(
                    "unknown option {other:?} (known: limit, cursor)"
                )))
            }
        }
    }
    match &state.cluster {
        Some(cluster) => Ok(Json(
            shared::list(cluster, scope(&who), limit, cursor).await?,
        )),
        None => Ok(Json(state.jobs.page(scope(&who), limit, cursor))),
    }
}

/// `GET /jobs/{id}`.
pub async fn get(
    State(state): State<Arc<AppState>>,
    Extension(who): Extension<Principal>,
    UrlPath(id): UrlPath<String>,
) -> Result<Json<JobView>, ApiError> {
    match &state.cluster {
        Some(cluster) => Ok(Json(shared::get(cluster, scope(&who), &id).await?)),
        None => Ok(Json(state.jobs.get(&id, scope(&who))?.view())),
    }
}

/// Streams one of a finished job's files, from this process's scratch
/// folder or from the shared bucket.
async fn file(
    state: &AppState,
    who: &Principal,
    id: &str,
    which: JobFile,
) -> Result<Response, ApiError> {
    if let Some(cluster) = &state.cluster {
        return shared::file(cluster, scope(who), id, which).await;
    }
    let job = state.jobs.get(id, scope(who))?;
    let path = {
        let inner = lock(&job.inner);
        if inner.state != JobState::Done {
            return Err(which.not_there(&job.id, inner.state, inner.error.as_deref()));
        }
        match &inner.scratch {
            Some(s) => s.file(&which.name(job.format)),
            None => return Err(ApiError::JobNotFound(id.to_string())),
        }
    };
    // Opened before answering: the file stays readable even if the job
    // expires or is deleted while it streams.
    let f = tokio::fs::File::open(&path)
        .await
        .map_err(|_| ApiError::JobNotFound(id.to_string()))?;
    let len = f.metadata().await.map(|m| m.len()).ok();
    let body = Body::from_stream(tokio_util::io::ReaderStream::new(f));
    Ok(which.response(&job.id, job.format, body, len))
}

/// `GET /jobs/{id}/output`.
pub async fn output(
    State(state): State<Arc<AppState>>,
    Extension(who): Extension<Principal>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ApiError> {
    file(&state, &who, &id, JobFile::Output).await
}

/// `GET /jobs/{id}/telemetry.csv`.
pub async fn telemetry(
    State(state): State<Arc<AppState>>,
    Extension(who): Extension<Principal>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ApiError> {
    file(&state, &who, &id, JobFile::Telemetry).await
}

/// `DELETE /jobs/{id}`: cancels a queued or running job (200 with its state,
/// once its ffmpeg children are gone and its files removed), or removes a
/// finished one and its files (204).
pub async fn delete(
    State(state): State<Arc<AppState>>,
    Extension(who): Extension<Principal>,
    UrlPath(id): UrlPath<String>,
) -> Result<Response, ApiError> {
    if let Some(cluster) = &state.cluster {
        return shared::delete(cluster, scope(&who), &id).await;
    }
    let job = state.jobs.get(&id, scope(&who))?;
    if job.cancel() {
        let mut settled = job.settled.subscribe();
        let _ = tokio::time::timeout(CANCEL_WAIT, settled.wait_for(|s| *s)).await;
        tracing::info!(job = %id, "job cancelled by request");
        return Ok(Json(job.view()).into_response());
    }
    state.jobs.remove(&id);
    Ok(StatusCode::NO_CONTENT.into_response())
}
