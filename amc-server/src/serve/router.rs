//! [`app`]: the routes, and the fallbacks that answer unknown paths and
//! methods with problem+json (the page's files when `--web-dir` has them).

use super::jobs;
use super::live;
use super::openapi;
use super::ops;
use super::problem::ApiError;
use super::stabilize;
use super::state::AppState;
use axum::extract::DefaultBodyLimit;
use axum::handler::HandlerWithoutStateExt;
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use std::sync::Arc;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::services::ServeDir;
use tower_http::trace::TraceLayer;

/// The router, separate from [`super::run`] so tests can drive it without a socket.
pub fn app(state: Arc<AppState>) -> Router {
    let api = Router::new()
        .route("/stabilize", post(stabilize::handler))
        .route("/jobs", post(jobs::create).get(jobs::list))
        .route("/jobs/{id}", get(jobs::get).delete(jobs::delete))
        .route("/jobs/{id}/output", get(jobs::output))
        .route("/jobs/{id}/telemetry.csv", get(jobs::telemetry))
        // Uploads are streamed to disk under our own limit.
        .layer(DefaultBodyLimit::disable())
        .route("/live", get(live::viewer))
        .route("/live/ingest", get(live::ingest))
        .route("/healthz", get(ops::healthz))
        .route("/metrics", get(ops::prometheus))
        .route("/openapi.json", get(openapi::document));
    let index = state.web_dir.join("index.html");
    let router = if index.is_file() {
        // The page's files; anything else is an unknown endpoint (problem+json 404).
        api.fallback_service(
            ServeDir::new(&state.web_dir).not_found_service(no_page.into_service()),
        )
    } else {
        api.fallback(no_page)
    };
    router
        .method_not_allowed_fallback(method_not_allowed)
        .layer(CatchPanicLayer::custom(super::panics::panic_response))
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

/// `/` when the page is not built, and unknown paths.
async fn no_page(uri: axum::http::Uri) -> Response {
    if uri.path() == "/" || uri.path() == "/index.html" {
        return Html(
            "<!doctype html><title>amc</title><h1>amc serve</h1>\
             <p>The web page is not built: run <code>bash web/build.sh</code> and start \
             <code>amc serve</code> from the repository root (or pass <code>--web-dir</code>).</p>\
             <p>The API is described at <a href=\"/openapi.json\">/openapi.json</a>.</p>",
        )
        .into_response();
    }
    ApiError::NoRoute(format!(
        "no such endpoint: {} (the API is described at /openapi.json)",
        uri.path()
    ))
    .into_response()
}

async fn method_not_allowed(method: axum::http::Method, uri: axum::http::Uri) -> Response {
    ApiError::MethodNotAllowed(format!(
        "{method} is not allowed on {} (the API is described at /openapi.json)",
        uri.path()
    ))
    .into_response()
}
