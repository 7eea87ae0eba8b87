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

/// The router, separate from [`super::run`] so tests can drive it without a socket.
pub fn app(state: Arc<AppState>) -> Router {
    let api = Router::new()
        .route("/stabilize", post(stabilize::handler))
        .route("/jobs", post(jobs::create).get(jobs::list))
        .route("/jobs/{id}", get(jobs::get).delete(jobs::delete))
        .route("/jobs/{id}/output", get(jobs::output))
        .route("/jobs/{id}/telemetry.csv", get(jobs::telemetry))
        .route("/jobs/{id}/telemetry", get(jobs::telemetry))
        // Uploads are streamed to disk under our own limit.
        .layer(DefaultBodyLimit::disable())
        .route("/live", get(live::viewer))
        .route("/live/ingest", get(live::ingest))
        .route("/live/ticket", post(live::ticket))
        .route("/healthz", get(ops::healthz))
        .route("/metrics", get(ops::prometheus))
        .route("/openapi.json", get(openapi::document));
    // The page's files, looked up per request (a page built after start-up
    // is served at once); anything else, and `/` while the page is not
    // built, goes to `no_page` (a note, or problem+json 404), whatever the
    // method.
    let page = ServeDir::new(&state.web_dir)
        .call_fallback_on_method_not_allowed(true)
        .fallback(no_page.into_service());
    let cors = super::headers::cors(&state.auth.config.cors_origins);
    // Innermost first: the access check sees every request but the CORS
    // preflights; the log line names each request, refused ones included.
    let router = api
        .fallback_service(page)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(axum::middleware::from_fn_with_state(
            state.auth.clone(),
            crate::auth::gate::check,
        ))
        .layer(CatchPanicLayer::custom(super::panics::panic_response))
        .layer(axum::middleware::from_fn(super::headers::secure))
        .layer(axum::middleware::from_fn(super::access::log));
    let router = match cors {
        Some(cors) => router.layer(cors),
        None => router,
    };
    router.with_state(state)
}

/// `/` when the page is not built, and unknown paths.
async fn no_page(uri: axum::http::Uri) -> Response {
    if uri.path() == "/" || uri.path() == "/index.html" {
        return Html(
            "<!doctype html><title>amc</title><h1>amc serve</h1>\
             <p>The web page is not built: run <code>bash web/build.sh</code> in the repository, \
             then reload this page (<code>amc serve</code> serves the folder given by \
             <code>--web-dir</code>, by default <code>web/dist</code> of the folder it was started in).</p>\
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
