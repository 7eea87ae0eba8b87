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
    let check = tokio::task::spawn_blocking(move || -> Result<(), Trouble> {
        amc_video::ffmpeg_available().map_err(|e| Trouble::new("ffmpeg", e))?;
        tempfile::tempfile_in(&work_dir)
            .map_err(|e| Trouble::new("the work dir", format!("work dir not writable: {e}")))?;
        Ok(())
    })
    .await
    .unwrap_or_else(|e| Err(Trouble::new("the health check", e)))
    // The API works without the live feed, but a source that cannot be
    // opened is something to fix: the probe says so.
    .and_then(|()| {
        state
            .live
            .source_error()
            .map_or(Ok(()), |e| Err(Trouble::new("the live source", e)))
    });
    // Without its database and bucket a replica can take no job.
    let check = match (check, &state.cluster) {
        (Ok(()), Some(cluster)) => cluster
            .ping()
            .await
            .map_err(|e| Trouble::new("the job database or bucket", e)),
        (check, _) => check,
    };
    let busy = state.limits.workers - state.cpu.available_permits().min(state.limits.workers);
    let public = state.auth.enabled();
    let mut live = state.live.status();
    if public {
        // A source URL can hold credentials (rtsp://user:pass@, srt's passphrase).
        if let Some(live) = live.as_object_mut() {
            live.remove("source");
        }
    }
    health(
        check,
        serde_json::json!({
            "workers": state.limits.workers,
            "busy": busy,
            "live": live,
        }),
        public,
    )
}

/// What a health check found broken: the part, for anyone, and the error,
/// which can name hosts, paths and source URLs.
pub(crate) struct Trouble {
    what: &'static str,
    detail: String,
}

impl Trouble {
    pub(crate) fn new(what: &'static str, detail: impl std::fmt::Display) -> Self {
        Self {
            what,
            detail: detail.to_string(),
        }
    }
}

/// The last trouble logged by a public `/healthz` (logged once per change,
/// not once per probe).
static LOGGED: std::sync::Mutex<Option<String>> = std::sync::Mutex::new(None);

/// The `/healthz` answer of a replica or a worker: 200 `ok` when `check`
/// passed, else 503 `unavailable` with its `detail`; then the version and
/// the caller's own `fields`. `public` (a service with keys, whose
/// `/healthz` anyone may ask): the detail names only the broken part, and
/// the error itself goes to the log.
pub(crate) fn health(
    check: Result<(), Trouble>,
    fields: serde_json::Value,
    public: bool,
) -> Response {
    let (code, status, detail) = match check {
        Ok(()) => (StatusCode::OK, "ok", None),
        Err(t) if public => {
            let mut logged = crate::poison::lock(&LOGGED);
            if logged.as_deref() != Some(t.detail.as_str()) {
                tracing::warn!(error = %t.detail, "/healthz: {} is not working", t.what);
                *logged = Some(t.detail);
            }
            (
                StatusCode::SERVICE_UNAVAILABLE,
                "unavailable",
                Some(format!(
                    "{} is not working (the service's log says why)",
                    t.what
                )),
            )
        }
        Err(t) => (
            StatusCode::SERVICE_UNAVAILABLE,
            "unavailable",
            Some(t.detail),
        ),
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
