//! Operations endpoints: `GET /healthz` (readiness) and `GET /metrics`
//! (OpenMetrics or Prometheus text, as the scraper asks).

use super::jobs::JobState;
use super::metrics::StateLabel;
use super::state::AppState;
use axum::extract::State;
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use std::collections::HashMap;
use std::sync::Arc;

/// `GET /healthz`: 200 while the service can work (ffmpeg runs, the work dir
/// is writable, the `--live-source` if any can be opened, and with
/// `--queue`/`--store` the database and the bucket answer); 503 with a
/// `detail` saying what is wrong otherwise.
pub async fn healthz(State(state): State<Arc<AppState>>) -> Response {
    let work_dir = state.work_dir.clone();
    let check = tokio::task::spawn_blocking(move || -> Result<(), String> {
        amc_video::ffmpeg_available().map_err(|e| e.to_string())?;
        tempfile::tempfile_in(&work_dir).map_err(|e| format!("work dir not writable: {e}"))?;
        Ok(())
    })
    .await
    .unwrap_or_else(|e| Err(e.to_string()))
    // The API works without the live feed, but a source that cannot be
    // opened is something to fix: the probe says so.
    .and_then(|()| state.live.source_error().map_or(Ok(()), Err));
    // Without its database and bucket a replica can take no job.
    let check = match (check, &state.cluster) {
        (Ok(()), Some(cluster)) => cluster.ping().await.map_err(|e| e.to_string()),
        (check, _) => check,
    };
    let busy = state.limits.workers - state.cpu.available_permits().min(state.limits.workers);
    health(
        check,
        serde_json::json!({
            "workers": state.limits.workers,
            "busy": busy,
            "live": state.live.status(),
        }),
    )
}

/// The `/healthz` answer of a replica or a worker: 200 `ok` when `check`
/// passed, else 503 `unavailable` with its `detail`; then the version and
/// the caller's own `fields`.
pub(crate) fn health(check: Result<(), String>, fields: serde_json::Value) -> Response {
    let (code, status, detail) = match check {
        Ok(()) => (StatusCode::OK, "ok", None),
        Err(e) => (StatusCode::SERVICE_UNAVAILABLE, "unavailable", Some(e)),
    };
    let mut body = serde_json::json!({
        "status": status,
        "detail": detail,
        "version": env!("CARGO_PKG_VERSION"),
    });
    if let (Some(body), serde_json::Value::Object(fields)) = (body.as_object_mut(), fields) {
        body.extend(fields);
    }
    (code, Json(body)).into_response()
}

/// `GET /metrics`.
pub async fn prometheus(State(state): State<Arc<AppState>>, headers: HeaderMap) -> Response {
    let counts: HashMap<JobState, usize> = match &state.cluster {
        None => state.jobs.counts(),
        Some(cluster) => match cluster.queue.counts().await {
            Ok(c) => {
                state.metrics.job_retries.set(c.retries);
                c.by_state
                    .iter()
                    .filter_map(|(s, n)| Some((JobState::parse(s)?, *n as usize)))
                    .collect()
            }
            // Stale counts would look like a healthy, idle queue: the scrape
            // fails (503) instead, and the scraper marks the target down.
            Err(e) => {
                tracing::warn!(error = %e, "cannot count jobs for /metrics");
                return state.refuse(e.into());
            }
        },
    };
    for s in JobState::ALL {
        state
            .metrics
            .jobs
            .get_or_create(&StateLabel { state: s.name() })
            .set(counts.get(&s).copied().unwrap_or(0) as i64);
    }
    state
        .metrics
        .queue_depth
        .set(counts.get(&JobState::Queued).copied().unwrap_or(0) as i64);
    state.metrics.disk_used.set(state.disk.used() as i64);
    state.metrics.response(headers.get(header::ACCEPT))
}
