//! What `POST /stabilize` and `POST /jobs` share: admission (or 503), the
//! options (or 400), the upload (or 400/413/415), its gyro log (or 400) and
//! its inspection (or 415/422).

use super::gyro_log;
use super::options::JobOptions;
use super::problem::{count, ApiError};
use super::state::AppState;
use super::storage::Scratch;
use super::upload::{self, Upload};
use super::work::{self, WorkSpec};
use crate::auth::limits::TenantSlot;
use crate::auth::Principal;
use amc_engine::RunControl;
use amc_video::Inspection;
use axum::body::BodyDataStream;
use axum::extract::Request;
use axum::http::request::Parts;
use std::sync::Arc;
use tokio::sync::OwnedSemaphorePermit;

/// An accepted request, ready to be processed.
pub struct Intake {
    /// Holds the request's place among those the service takes at once.
    pub admission: OwnedSemaphorePermit,
    pub options: JobOptions,
    /// The request's query string, as sent (the shared job table keeps it
    /// for the worker, which parses it again).
    pub query: String,
    pub scratch: Scratch,
    pub upload: Upload,
    pub inspection: Inspection,
    /// The tenant's slot (with keys: `--max-jobs-per-tenant`), held until
    /// the work is done or handed to the shared job table.
    pub tenant_slot: Option<TenantSlot>,
}

/// An accepted upload to be processed on this replica. Dropped, its scratch
/// folder goes before its admission permit.
pub struct LocalWork {
    /// The run: its output (and telemetry, when asked for) in `scratch`.
    pub spec: WorkSpec,
    /// Cancels the run; counts its frames against the job time limit.
    pub control: Arc<RunControl>,
    /// The upload's size, bytes.
    pub bytes: u64,
    /// The frames the inspection counted, when it could.
    pub frames: Option<u64>,
    pub scratch: Scratch,
    /// Holds the request's place among those the service takes at once.
    pub admission: OwnedSemaphorePermit,
    pub tenant_slot: Option<TenantSlot>,
}

impl Intake {
    /// The upload as a run on this replica (`POST /stabilize`, and
    /// `POST /jobs` without the shared job table), with a telemetry file
    /// when `with_telemetry`.
    pub fn into_local(self, state: &AppState, with_telemetry: bool) -> LocalWork {
        let Intake {
            admission,
            options,
            query: _,
            scratch,
            upload,
            inspection,
            tenant_slot,
        } = self;
        let bytes = upload.bytes;
        let spec = WorkSpec::for_upload(&scratch, upload, options, &inspection, with_telemetry);
        LocalWork {
            spec,
            control: work::control(state),
            bytes,
            frames: inspection.info.frame_count,
            scratch,
            admission,
            tenant_slot,
        }
    }
}

/// Admits, parses and receives `request`. When it is refused before its
/// body was read, the rest of the body is read and discarded in the
/// background so the client gets the answer rather than a reset connection.
pub async fn accept(
    state: &Arc<AppState>,
    who: &Principal,
    request: Request,
) -> Result<Intake, ApiError> {
    let (parts, body) = request.into_parts();
    let mut body = Some(body.into_data_stream());
    let result = accept_parts(state, who, &parts, &mut body).await;
    if result.is_err() {
        if let Some(rest) = body.take() {
            upload::linger(rest);
        }
    }
    result
}

async fn accept_parts(
    state: &Arc<AppState>,
    who: &Principal,
    parts: &Parts,
    body: &mut Option<BodyDataStream>,
) -> Result<Intake, ApiError> {
    let options = JobOptions::from_query(parts.uri.query())?;
    let tenant_slot = state.auth.take_slot(who)?;
    let admission = state.admission.clone().try_acquire_owned().map_err(|_| {
        ApiError::Saturated(format!(
            "the service is busy: {} being processed or queued (--workers {} plus --max-queued {}); try again shortly",
            count((state.limits.workers + state.limits.queue) as u64, "clip is", "clips are"),
            state.limits.workers,
            state.limits.queue
        ))
    })?;
    let scratch = Scratch::new(&state.work_dir, state.disk.clone())
        .map_err(|e| ApiError::Internal(format!("cannot create scratch space: {e}")))?;
    let upload = upload::receive(
        &parts.headers,
        body,
        &scratch,
        state.limits.max_upload_bytes,
        !options.gyro,
    )
    .await?;
    if let Some(log) = &upload.gyro {
        gyro_log::check(log).await?;
    }
    let video = upload.video.clone();
    let limits = state.limits.clone();
    let inspection = tokio::task::spawn_blocking(move || work::inspect(&video, &limits))
        .await
        .map_err(|e| ApiError::Internal(format!("inspection failed: {e}")))??;
    Ok(Intake {
        admission,
        options,
        query: parts.uri.query().unwrap_or("").to_string(),
        scratch,
        upload,
        inspection,
        tenant_slot,
    })
}
