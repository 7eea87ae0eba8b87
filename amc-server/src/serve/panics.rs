//! Panics in the service. A bug must cost one request or one job, never the
//! service: tokio catches the unwind of a handler's task (the router's
//! catch-panic layer answers it with a 500 problem+json) and of a worker's
//! blocking thread (its job fails with the reason, or `POST /stabilize`
//! answers 500; see [`super::work::stabilize_on_worker`]). The hook installed
//! here logs each panic once, through the service's log (JSON with
//! `--log-json`), with its location and backtrace.

use super::problem::ApiError;
use axum::response::{IntoResponse, Response};
use std::any::Any;

/// The detail a client gets for a panic (the log has the rest).
pub const PANICKED: &str =
    "internal error while processing; the clip was not stabilized (the server logged the details)";

/// Replaces the default hook (a plain line on stderr) with a log event.
pub fn install_hook() {
    std::panic::set_hook(Box::new(|info| {
        let backtrace = std::backtrace::Backtrace::force_capture();
        let location = info
            .location()
            .map(|l| l.to_string())
            .unwrap_or_else(|| "unknown".into());
        let thread = std::thread::current();
        tracing::error!(
            target: "amc::panic",
            payload = payload_text(info.payload()),
            location = %location,
            thread = thread.name().unwrap_or("unnamed"),
            backtrace = %backtrace,
            "panic"
        );
    }));
}

/// The text of a panic's payload (`panic!` gives a `&str` or a `String`).
pub fn payload_text(payload: &(dyn Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("(a non-text payload)")
}

/// The answer to a request whose handler panicked (tower-http's catch-panic layer).
pub fn panic_response(_payload: Box<dyn Any + Send + 'static>) -> Response {
    ApiError::Internal(PANICKED.into()).into_response()
}
