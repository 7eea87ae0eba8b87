//! One log line per request, once it is answered: its method, its path
//! (never the query string, nor any header: nothing a client sends as a key
//! or a token reaches the log), the status and how long the answer took
//! (until the response's head; a streamed body goes on after it), with the
//! problem's `detail` when refused. 5xx other than 503 are logged at ERROR,
//! the rest at INFO. A request whose client went away before the answer
//! (its handler dropped: the work is cancelled) gets its line too. Used by
//! `amc serve`'s router and `amc worker`'s endpoints.

use super::problem::Refusal;
use axum::extract::Request;
use axum::http::{Method, StatusCode};
use axum::middleware::Next;
use axum::response::Response;
use std::time::Instant;

/// Longest path logged, in bytes; a longer one is cut (and says so).
const MAX_PATH: usize = 200;

/// The request being answered; logs "client went away" if dropped unanswered.
struct Pending {
    method: Method,
    path: String,
    start: Instant,
    answered: bool,
}

impl Pending {
    fn ms(&self) -> f64 {
        (self.start.elapsed().as_secs_f64() * 10_000.0).round() / 10.0
    }
}

impl Drop for Pending {
    fn drop(&mut self) {
        if !self.answered {
            tracing::info!(
                method = %self.method,
                path = %self.path,
                ms = self.ms(),
                "request abandoned: the client went away before the answer"
            );
        }
    }
}

/// The path as logged: at most [`MAX_PATH`] bytes, cut on a character boundary.
fn loggable(path: &str) -> String {
    if path.len() <= MAX_PATH {
        return path.to_string();
    }
    let mut end = MAX_PATH;
    while !path.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}... ({} bytes)", &path[..end], path.len())
}

/// The middleware (`axum::middleware::from_fn(access::log)`).
pub async fn log(request: Request, next: Next) -> Response {
    let mut pending = Pending {
        method: request.method().clone(),
        path: loggable(request.uri().path()),
        start: Instant::now(),
        answered: false,
    };
    let res = next.run(request).await;
    pending.answered = true;
    let status = res.status();
    let (method, path, ms) = (&pending.method, &pending.path, pending.ms());
    let code = status.as_u16();
    match res.extensions().get::<Refusal>() {
        Some(Refusal(why))
            if status.is_server_error() && status != StatusCode::SERVICE_UNAVAILABLE =>
        {
            tracing::error!(%method, %path, status = code, ms, error = %why, "request failed")
        }
        Some(Refusal(why)) => {
            tracing::info!(%method, %path, status = code, ms, error = %why, "request refused")
        }
        None if status.is_server_error() && status != StatusCode::SERVICE_UNAVAILABLE => {
            tracing::error!(%method, %path, status = code, ms, "request failed")
        }
        None => tracing::info!(%method, %path, status = code, ms, "request answered"),
    }
    res
}

#[cfg(test)]
mod tests {
    #[test]
    fn long_paths_are_cut_on_a_character_boundary() {
        assert_eq!(super::loggable("/jobs"), "/jobs");
        let long = format!("/{}", "é".repeat(150));
        let cut = super::loggable(&long);
        assert!(cut.len() < 230 && cut.ends_with("(301 bytes)"), "{cut}");
    }
}
