//! The job endpoints when jobs live in the shared job table (`amc serve
//! --queue URL --store s3://BUCKET`): any replica answers for any job.
//!
//! `POST /jobs` receives and inspects the upload in a local scratch folder
//! as always (so a bad clip is refused at once, 4xx), streams it into the
//! bucket, inserts the job's row and removes the local copy; `amc worker`s
//! do the rest. Reads come from the row; outputs are streamed from the
//! bucket. A database or bucket that is down answers 503 with
//! `Retry-After`.

use super::view::{progress, rfc3339, valid_id, JobFile, JobMetrics, JobMotion, JobPage};
use super::view::{JobState, JobSummary, JobView};
use crate::cluster::queue::{JobRow, NewJob};
use crate::cluster::Cluster;
use crate::serve::intake::Intake;
use crate::serve::options::OutputFormat;
use crate::serve::problem::ApiError;
use axum::body::Body;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;
use std::time::{Duration, Instant, SystemTime};

/// Longest a `DELETE` waits for a running job's worker to let go of it.
const CANCEL_WAIT: Duration = Duration::from_secs(15);

/// A job as the endpoints show it, from its row.
fn view(row: &JobRow) -> JobView {
    // The table's CHECK allows only the five names.
    let state = JobState::parse(&row.state).unwrap_or(JobState::Failed);
    let frames_done = row.frames_done.max(0) as u64;
    let frames_total = row.frames_total.map(|n| n.max(0) as u64);
    let done = state == JobState::Done;
    let format = OutputFormat::from_extension(&row.format).unwrap_or(OutputFormat::Mp4);
    JobView {
        summary: JobSummary {
            id: row.id.clone(),
            state,
            created: rfc3339(created(row)),
            frames_done,
            frames_total,
            progress: progress(state, frames_done, frames_total),
        },
        format: format.extension(),
        error: row.error.clone(),
        metrics: row
            .metrics
            .as_deref()
            .and_then(|j| serde_json::from_str::<JobMetrics>(j).ok()),
        motion: row
            .motion
            .as_deref()
            .and_then(|j| serde_json::from_str::<JobMotion>(j).ok()),
        output: done.then(|| format!("/jobs/{}/output", row.id)),
        telemetry: done.then(|| format!("/jobs/{}/telemetry.csv", row.id)),
    }
}

fn created(row: &JobRow) -> SystemTime {
    SystemTime::UNIX_EPOCH + Duration::from_secs_f64(row.created.max(0.0))
}

fn summary(row: &JobRow) -> JobSummary {
    view(row).summary
}

/// `POST /jobs`: the accepted upload goes into the bucket, the job into the table.
pub async fn create(
    cluster: &Cluster,
    id: String,
    tenant: &str,
    intake: Intake,
) -> Result<JobView, ApiError> {
    let Intake {
        admission,
        options,
        query,
        scratch,
        upload,
        inspection,
        tenant_slot,
    } = intake;
    let key = cluster.store.input_key(tenant, &id);
    cluster.store.put_file(&key, &upload.video).await?;
    // The client's gyro log goes beside the upload, under the job's
    // prefix: removed with the upload, and with the job's other objects.
    let gyro_key = match &upload.gyro {
        Some(log) => {
            let ext = log.extension().and_then(|e| e.to_str());
            let gyro_key = cluster.store.gyro_key(tenant, &id, ext);
            if let Err(e) = cluster.store.put_file(&gyro_key, log).await {
                let _ = cluster.store.delete(&key).await;
                return Err(e.into());
            }
            Some(gyro_key)
        }
        None => None,
    };
    let job = NewJob {
        id: &id,
        tenant,
        options: &query,
        format: options.format.extension(),
        lens: upload.lens.as_deref(),
        width: inspection.info.width as i32,
        height: inspection.info.height as i32,
        input_key: &key,
        gyro_key: gyro_key.as_deref(),
        frames_total: inspection.info.frame_count.map(|n| n as i64),
    };
    let row = match cluster.queue.insert(&job).await {
        Ok(row) => row,
        Err(e) => {
            // Nothing the client sent is kept for a job that does not exist.
            for k in std::iter::once(&key).chain(&gyro_key) {
                if let Err(d) = cluster.store.delete(k).await {
                    tracing::warn!(job = %id, error = %d, "cannot remove the upload of a job that was not queued");
                }
            }
            return Err(e.into());
        }
    };
    tracing::info!(job = %id, bytes = upload.bytes, frames = ?job.frames_total, store = %cluster.store.location, "job queued");
    // The local copy goes; the bucket has it.
    drop(scratch);
    drop(admission);
    drop(tenant_slot);
    Ok(view(&row))
}

/// The job's row, if `tenant` may see it (`None`: every tenant's): another
/// tenant's job is unknown, exactly as a missing one.
async fn row(cluster: &Cluster, tenant: Option<&str>, id: &str) -> Result<JobRow, ApiError> {
    let unknown = || ApiError::JobNotFound(id.chars().take(64).collect());
    if !valid_id(id) {
        return Err(unknown());
    }
    // Ids are stored in lowercase, as they are made.
    cluster
        .queue
        .get(&id.to_ascii_lowercase())
        .await?
        .filter(|r| tenant.is_none_or(|t| r.tenant == t))
        .ok_or_else(unknown)
}

/// `GET /jobs/{id}`.
pub async fn get(cluster: &Cluster, tenant: Option<&str>, id: &str) -> Result<JobView, ApiError> {
    Ok(view(&row(cluster, tenant, id).await?))
}

/// `GET /jobs`: a page of jobs, newest first.
pub async fn list(
    cluster: &Cluster,
    tenant: Option<&str>,
    limit: usize,
    cursor: Option<u64>,
) -> Result<JobPage, ApiError> {
    let before = cursor.map(|c| c.min(i64::MAX as u64) as i64);
    let (rows, more) = cluster.queue.page(tenant, limit, before).await?;
    Ok(JobPage {
        next_cursor: more
            .then(|| rows.last().map(|r| r.seq.to_string()))
            .flatten(),
        jobs: rows.iter().map(summary).collect(),
    })
}

/// Streams a finished job's output or telemetry from the bucket.
pub async fn file(
    cluster: &Cluster,
    tenant: Option<&str>,
    id: &str,
    which: JobFile,
) -> Result<Response, ApiError> {
    let row = row(cluster, tenant, id).await?;
    let state = JobState::parse(&row.state).unwrap_or(JobState::Failed);
    if state != JobState::Done {
        return Err(which.not_there(&row.id, state, row.error.as_deref()));
    }
    let format = OutputFormat::from_extension(&row.format).unwrap_or(OutputFormat::Mp4);
    let key = match which {
        JobFile::Output => row.output_key.as_deref(),
        JobFile::Telemetry => row.telemetry_key.as_deref(),
    };
    let key = key.ok_or_else(|| ApiError::JobNotFound(id.to_string()))?;
    let (len, stream) = match cluster.store.open(key).await {
        Ok(found) => found,
        // Expired (or removed) between the row's read and this one.
        Err(e) if e.not_found() => return Err(ApiError::JobNotFound(id.to_string())),
        Err(e) => return Err(e.into()),
    };
    Ok(which.response(&row.id, format, Body::from_stream(stream), Some(len)))
}

/// `DELETE /jobs/{id}`: cancels a queued or running job (200 with its
/// state, once its worker has let go of it, or after `CANCEL_WAIT`), or
/// removes a finished one with its objects (204).
pub async fn delete(
    cluster: &Cluster,
    tenant: Option<&str>,
    id: &str,
) -> Result<Response, ApiError> {
    let row = row(cluster, tenant, id).await?;
    if let Some(mut row) = cluster.queue.cancel(&row.id).await? {
        tracing::info!(job = %row.id, "job cancelled by request");
        let start = Instant::now();
        // The worker notices within its renewal period (half a second).
        while !row.released && start.elapsed() < CANCEL_WAIT {
            tokio::time::sleep(Duration::from_millis(100)).await;
            match cluster.queue.get(&row.id).await? {
                Some(r) => row = r,
                None => break,
            }
        }
        return Ok(Json(view(&row)).into_response());
    }
    let store = &cluster.store;
    let removed = cluster
        .queue
        .remove_finished(&row.id, |id, tenant| async move {
            store.delete_job(&tenant, &id).await.map(|_| ())
        })
        .await?;
    if !removed {
        return Err(ApiError::JobNotFound(id.to_string()));
    }
    tracing::info!(job = %row.id, "job removed by request");
    Ok(StatusCode::NO_CONTENT.into_response())
}
