//! The worker's operations endpoints: `GET /healthz` (ffmpeg, the
//! database and the bucket) and `GET /metrics` (the job table's counts and
//! this worker's runs, in OpenMetrics or Prometheus' text format, as the
//! scraper asks). Anything else is a
//! problem+json 404.

use super::state::WorkerState;
use crate::serve::jobs::JobState;
use crate::serve::metrics::StateLabel;
use crate::serve::ops::{health, Trouble};
use crate::serve::problem::ApiError;
use axum::extract::State;
use axum::http::{header, HeaderMap};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use std::sync::atomic::Ordering;
use std::sync::Arc;

/// With `--auth-keys`, `/metrics` needs an `admin` key (as on the replicas).
pub(super) fn app(state: Arc<WorkerState>, auth: Arc<crate::auth::Auth>) -> Router {
    // With keys, /healthz is still open to all: it names no host or path.
    let public = auth.enabled();
    Router::new()
        .route("/healthz", get(move |state| healthz(state, public)))
        .route("/metrics", get(metrics))
        .fallback(|uri: axum::http::Uri| async move {
            ApiError::NoRoute(format!(
                "no such endpoint: {} (a worker serves /healthz and /metrics)",
                uri.path()
            ))
        })
        .layer(axum::middleware::from_fn_with_state(
            auth,
            crate::auth::gate::check,
        ))
        .layer(axum::middleware::from_fn(crate::serve::access::log))
        .with_state(state)
}

/// 200 while the worker can run jobs; 503 naming what is down.
async fn healthz(State(state): State<Arc<WorkerState>>, public: bool) -> Response {
    let check = match tokio::task::spawn_blocking(amc_video::ffmpeg_available).await {
        Ok(Ok(())) => state
            .cluster
            .ping()
            .await
            .map_err(|e| Trouble::new("the job database or bucket", e)),
        Ok(Err(e)) => Err(Trouble::new("ffmpeg", e)),
        Err(e) => Err(Trouble::new("the health check", e)),
    };
    health(
        check,
        serde_json::json!({
            "role": "worker",
            "worker": state.name,
            "threads": state.limits.threads,
            "busy": state.busy.load(Ordering::SeqCst),
        }),
        public,
    )
}

async fn metrics(State(state): State<Arc<WorkerState>>, headers: HeaderMap) -> Response {
    let counts = match state.cluster.queue.counts().await {
        Ok(c) => c,
        Err(e) => return ApiError::from(e).into_response(),
    };
    let m = &state.metrics;
    for s in JobState::ALL {
        let n = counts
            .by_state
            .iter()
            .find(|(name, _)| name == s.name())
            .map_or(0, |(_, n)| *n);
        m.jobs.get_or_create(&StateLabel { state: s.name() }).set(n);
        if s == JobState::Queued {
            m.queue_depth.set(n);
        }
    }
    m.job_retries.set(counts.retries);
    m.response(headers.get(header::ACCEPT))
}
