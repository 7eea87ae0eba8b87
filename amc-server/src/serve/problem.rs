//! Errors of the service, answered as RFC 9457 `application/problem+json`.
//!
//! Every variant maps to one status a client can act on; none of them is a
//! 500 caused by what a client sent. The `detail` is one line naming the bad
//! value and what is allowed.

use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use thiserror::Error;

/// `n` and the noun in its number: `1 clip`, `2 clips` (for messages).
pub fn count(n: impl Into<u64>, one: &str, many: &str) -> String {
    let n = n.into();
    format!("{n} {}", if n == 1 { one } else { many })
}

/// Seconds a saturated service asks clients to wait before retrying.
pub const RETRY_AFTER_SECS: u64 = 5;

#[derive(Debug, Error)]
pub enum ApiError {
    /// A query option (or form field) with a bad value; names it and the allowed range.
    #[error("{0}")]
    BadOption(String),
    /// A malformed request (empty body, missing field, broken upload).
    #[error("{0}")]
    BadRequest(String),
    /// The upload is larger than `--max-upload-mb`.
    #[error("the upload is larger than the limit of {limit_mb} MB (set by --max-upload-mb)")]
    TooLarge { limit_mb: u64 },
    /// A `gyro` form field over its own limit (`upload::MAX_GYRO_BYTES`).
    #[error("the gyro log is larger than the limit of {limit_mib} MiB")]
    GyroTooLarge { limit_mib: u64 },
    /// A `gyro` form field whose file is no gyro log, holds no gyroscope
    /// samples, or comes with `gyro=off`: well-formed, but nothing the run
    /// could use (as an undecodable video is).
    #[error("{0}")]
    UnusableGyro(String),
    /// Not a video ffmpeg can decode (or a content type that is not video).
    #[error("{0}")]
    Unsupported(String),
    /// A video over the size or duration limits, or one the stabilizer cannot process.
    #[error("{0}")]
    Unprocessable(String),
    /// No key, a wrong key or a used ticket: 401 with `WWW-Authenticate: Bearer`.
    #[error("{0}")]
    Unauthorized(String),
    /// A valid key without the endpoint's role, or a foreign `Origin`.
    #[error("{0}")]
    Forbidden(String),
    /// A key over its rate, an address over its failed keys, a tenant at
    /// its jobs: 429 with `Retry-After`.
    #[error("{detail}")]
    TooManyRequests { detail: String, retry_after_s: u64 },
    #[error("{0}")]
    NoRoute(String),
    #[error("{0}")]
    MethodNotAllowed(String),
    /// A plain HTTP request to a WebSocket endpoint.
    #[error("{0}")]
    UpgradeRequired(String),
    #[error("no job with id {0:?} (jobs expire after --job-ttl seconds)")]
    JobNotFound(String),
    /// The job exists but has nothing of that kind (yet).
    #[error("{0}")]
    Conflict(String),
    /// Too many requests or jobs in flight, or the disk budget is used up.
    #[error("{0}")]
    Saturated(String),
    /// A dependency (the job table's database, the object store) is down:
    /// answered 503 with `Retry-After`, as the service recovers by itself.
    #[error("{0}")]
    Unavailable(String),
    /// The server cannot work (ffmpeg missing, disk error): not the client's fault.
    #[error("{0}")]
    Internal(String),
}

impl From<crate::cluster::ClusterError> for ApiError {
    /// A dependency that is down is 503 (try again); anything else about the
    /// shared job table or store is the server's problem.
    fn from(e: crate::cluster::ClusterError) -> Self {
        if e.unreachable() {
            ApiError::Unavailable(format!(
                "the service cannot reach its {}; try again shortly",
                e
            ))
        } else {
            ApiError::Internal(e.to_string())
        }
    }
}

/// Why a request was refused (its problem's `detail`), carried on the
/// response for the request's log line.
#[derive(Clone, Debug)]
pub struct Refusal(pub String);

#[derive(Serialize)]
struct Problem<'a> {
    #[serde(rename = "type")]
    kind: &'a str,
    title: &'a str,
    status: u16,
    detail: String,
}

impl ApiError {
    pub fn status(&self) -> StatusCode {
        match self {
            ApiError::BadOption(_) | ApiError::BadRequest(_) => StatusCode::BAD_REQUEST,
            ApiError::TooLarge { .. } | ApiError::GyroTooLarge { .. } => {
                StatusCode::PAYLOAD_TOO_LARGE
            }
            ApiError::Unsupported(_) => StatusCode::UNSUPPORTED_MEDIA_TYPE,
            ApiError::Unprocessable(_) | ApiError::UnusableGyro(_) => {
                StatusCode::UNPROCESSABLE_ENTITY
            }
            ApiError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            ApiError::Forbidden(_) => StatusCode::FORBIDDEN,
            ApiError::TooManyRequests { .. } => StatusCode::TOO_MANY_REQUESTS,
            ApiError::JobNotFound(_) | ApiError::NoRoute(_) => StatusCode::NOT_FOUND,
            ApiError::MethodNotAllowed(_) => StatusCode::METHOD_NOT_ALLOWED,
            ApiError::UpgradeRequired(_) => StatusCode::UPGRADE_REQUIRED,
            ApiError::Conflict(_) => StatusCode::CONFLICT,
            ApiError::Saturated(_) | ApiError::Unavailable(_) => StatusCode::SERVICE_UNAVAILABLE,
            ApiError::Internal(_) => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }

    /// A short, stable identifier of the kind of problem (the `type` URI's last part).
    pub fn kind(&self) -> &'static str {
        match self {
            ApiError::BadOption(_) => "bad-option",
            ApiError::BadRequest(_) => "bad-request",
            ApiError::TooLarge { .. } | ApiError::GyroTooLarge { .. } => "too-large",
            ApiError::Unsupported(_) => "unsupported-media",
            ApiError::Unprocessable(_) => "unprocessable-video",
            ApiError::UnusableGyro(_) => "unusable-gyro-log",
            ApiError::JobNotFound(_) => "job-not-found",
            ApiError::Unauthorized(_) => "unauthorized",
            ApiError::Forbidden(_) => "forbidden",
            ApiError::TooManyRequests { .. } => "too-many-requests",
            ApiError::NoRoute(_) => "not-found",
            ApiError::MethodNotAllowed(_) => "method-not-allowed",
            ApiError::UpgradeRequired(_) => "upgrade-required",
            ApiError::Conflict(_) => "conflict",
            ApiError::Saturated(_) => "saturated",
            ApiError::Unavailable(_) => "unavailable",
            ApiError::Internal(_) => "internal",
        }
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        let retry_after = match &self {
            ApiError::TooManyRequests { retry_after_s, .. } => Some(*retry_after_s),
            _ if status == StatusCode::SERVICE_UNAVAILABLE => Some(RETRY_AFTER_SECS),
            _ => None,
        };
        let kind = format!("/problems/{}", self.kind());
        let body = Problem {
            kind: &kind,
            title: status.canonical_reason().unwrap_or("Error"),
            status: status.as_u16(),
            detail: self.to_string(),
        };
        let json = serde_json::to_vec(&body).unwrap_or_default();
        let mut res = (status, json).into_response();
        // The request's one log line (`super::access`) says why.
        res.extensions_mut().insert(Refusal(body.detail));
        res.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        if status == StatusCode::UPGRADE_REQUIRED {
            res.headers_mut()
                .insert(header::UPGRADE, HeaderValue::from_static("websocket"));
        }
        if let Some(secs) = retry_after {
            res.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(secs));
        }
        if status == StatusCode::UNAUTHORIZED {
            res.headers_mut().insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"amc\""),
            );
        }
        res
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn counts_agree_in_number() {
        assert_eq!(super::count(1u64, "clip is", "clips are"), "1 clip is");
        assert_eq!(super::count(0u64, "clip is", "clips are"), "0 clips are");
        assert_eq!(super::count(3u64, "frame", "frames"), "3 frames");
    }
}
