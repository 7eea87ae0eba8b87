//! `POST /stabilize`: the clip in, the stabilized clip streamed back, the
//! clip's summary metrics in `X-Amc-*` response headers.
//!
//! If the client goes away, axum drops this handler's future; the
//! [`CancelOnDrop`] guard then cancels the run, which kills its ffmpeg
//! children, and the scratch folder is removed with the future.

use super::intake;
use super::panics::PANICKED;
use super::problem::ApiError;
use super::state::AppState;
use super::work;
use amc_engine::{RunControl, RunSummary};
use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, HeaderName, HeaderValue};
use axum::response::Response;
use futures_util::StreamExt;
use std::sync::Arc;

/// Cancels a run when the request handling it is dropped before it is disarmed.
struct CancelOnDrop(Option<Arc<RunControl>>);

impl CancelOnDrop {
    fn disarm(mut self) {
        self.0 = None;
    }
}

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        if let Some(c) = &self.0 {
            c.cancel();
        }
    }
}

/// Counts a request in flight for `/metrics` while it lives.
struct InFlight<'a>(&'a AppState);

impl<'a> InFlight<'a> {
    fn new(state: &'a AppState) -> Self {
        state.metrics.in_flight.inc();
        Self(state)
    }
}

impl Drop for InFlight<'_> {
    fn drop(&mut self) {
        self.0.metrics.in_flight.dec();
    }
}

pub async fn handler(State(state): State<Arc<AppState>>, request: Request) -> Response {
    let _in_flight = InFlight::new(&state);
    stabilize(&state, request)
        .await
        .unwrap_or_else(|e| state.refuse(e))
}

async fn stabilize(state: &Arc<AppState>, request: Request) -> Result<Response, ApiError> {
    let who = crate::auth::gate::principal(&request)?;
    let local = intake::accept(state, &who, request)
        .await?
        .into_local(state, false);
    let format = local.spec.options.format;
    let guard = CancelOnDrop(Some(local.control.clone()));
    let permit = state
        .cpu
        .clone()
        .acquire_owned()
        .await
        .map_err(|_| ApiError::Saturated("the service is shutting down".into()))?;
    let (spec, result) = work::stabilize_on_worker(state, local.spec, local.control)
        .await
        .map_err(|_| ApiError::Internal(PANICKED.into()))?;
    drop(permit);
    let summary = result?;
    guard.disarm();
    local.scratch.remove(&spec.input);
    if let Some(log) = &spec.gyro_log {
        local.scratch.remove(log);
    }
    let file = tokio::fs::File::open(&spec.output)
        .await
        .map_err(|e| ApiError::Internal(format!("cannot read the result: {e}")))?;
    let len = file.metadata().await.map(|m| m.len()).ok();
    // The scratch folder (and the admission permit) live as long as the
    // body streams, and go when it ends or the client disconnects.
    let keep = (local.scratch, local.admission, local.tenant_slot);
    let stream = tokio_util::io::ReaderStream::new(file).map(move |chunk| {
        let _ = &keep;
        chunk
    });
    let mut res = Response::new(Body::from_stream(stream));
    let h = res.headers_mut();
    h.insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static(format.content_type()),
    );
    if let Some(len) = len {
        h.insert(header::CONTENT_LENGTH, HeaderValue::from(len));
    }
    if let Ok(v) = HeaderValue::from_str(&format!(
        "attachment; filename=\"stabilized.{}\"",
        format.extension()
    )) {
        h.insert(header::CONTENT_DISPOSITION, v);
    }
    summary_headers(h, &summary);
    Ok(res)
}

/// The clip's summary as `X-Amc-*` headers (and their names, for CORS exposure).
pub const SUMMARY_HEADERS: &[&str] = &[
    "x-amc-frames",
    "x-amc-output-size",
    "x-amc-processing-fps",
    "x-amc-rms-normal-flow",
    "x-amc-rms-frame-change",
    "x-amc-sharpness",
    "x-amc-valid-fraction",
    "x-amc-rms-speed-estimate-dps",
    "x-amc-rms-speed-view-dps",
    "x-amc-saccades",
    "x-amc-readout-ms",
    "x-amc-warning",
];

fn summary_headers(h: &mut HeaderMap, s: &RunSummary) {
    let mut put = |name: &'static str, value: String| {
        if let Ok(v) = HeaderValue::from_str(&value) {
            h.insert(HeaderName::from_static(name), v);
        }
    };
    put("x-amc-frames", s.frames.to_string());
    put(
        "x-amc-output-size",
        format!("{}x{}", s.output_size.0, s.output_size.1),
    );
    put(
        "x-amc-processing-fps",
        format!("{:.1}", s.frames_per_second),
    );
    let motion = &s.motion;
    put(
        "x-amc-valid-fraction",
        format!("{:.5}", motion.valid_fraction),
    );
    put(
        "x-amc-rms-speed-estimate-dps",
        format!("{:.3}", motion.rms_speed_est_dps),
    );
    put(
        "x-amc-rms-speed-view-dps",
        format!("{:.3}", motion.rms_speed_view_dps),
    );
    put("x-amc-saccades", motion.saccades.to_string());
    put("x-amc-readout-ms", format!("{}", s.readout_ms));
    // The image metrics cost about as much as stabilizing; `metrics=false` skips them.
    if let Some(m) = &s.metrics {
        put("x-amc-rms-normal-flow", format!("{:.5}", m.rms_normal_flow));
        put("x-amc-rms-frame-change", format!("{:.6}", m.rms_change));
        put("x-amc-sharpness", format!("{:.6}", m.sharpness));
    }
    // One `X-Amc-Warning` line per warning, in the order they arose: a
    // warning's text has commas and semicolons of its own, so no joined
    // value could be split again.
    for w in &s.warnings {
        if let Ok(v) = HeaderValue::from_str(w) {
            h.append(HeaderName::from_static("x-amc-warning"), v);
        }
    }
}
