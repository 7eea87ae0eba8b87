//! `amc serve`: the HTTP service.
//!
//! | route | what |
//! |---|---|
//! | `POST /stabilize` | clip in (raw body, or multipart with an optional lens file and gyro log), stabilized clip out, metrics in `X-Amc-*` headers |
//! | `POST /jobs`, `GET /jobs`, `GET/DELETE /jobs/{id}`, `GET /jobs/{id}/output`, `GET /jobs/{id}/telemetry.csv` | batch jobs |
//! | `GET /live` (WebSocket) | the stabilized live feed: a JPEG then a JSON telemetry message per frame |
//! | `GET /live/ingest` (WebSocket) | a publisher's JPEG frames, when there is no `--live-source` |
//! | `POST /live/ticket` | a single-use ticket for a browser's WebSocket (`?ticket=`) |
//! | `GET /healthz`, `GET /metrics`, `GET /openapi.json` | operations |
//! | `GET /` | the web page (`--web-dir`) |
//!
//! With `--auth-keys`, every route but `/healthz` and the page's files needs
//! a key with the route's role (`crate::auth`, docs/security.md).
//!
//! CPU work runs on blocking threads, at most `--workers` at once (a
//! semaphore); at most `--workers + --max-queued` clips are accepted at once and
//! the rest get 503 with `Retry-After`. Uploads and results live in
//! per-request scratch folders under the work directory, removed with their
//! request or job, and the work directory itself is removed on shutdown.
//!
//! Layers, each using only those below it: `config` (flags, limits) and
//! `problem`, `options`, `storage`, `metrics`, `gyro_log` at the bottom; `live` (its hub)
//! and `jobs` (its store); `state` (what handlers share); `work`, `intake`;
//! the handlers (`stabilize`, `jobs`, `live`, `ops`, `openapi`); `access`
//! (each request's log line), `headers` (CSP, CORS); `router` (routes,
//! fallbacks, layers); `listen` (connections: limits, header timeouts, TLS);
//! `run` (the process: logs, runtime, shutdown). This file only declares and re-exports.

pub(crate) mod access;
pub(crate) mod config;
#[doc(hidden)]
pub mod fuzzing;
pub(crate) mod gyro_log;
mod headers;
pub(crate) mod intake;
pub(crate) mod jobs;
mod listen;
mod live;
pub(crate) mod metrics;
mod openapi;
pub(crate) mod ops;
pub(crate) mod options;
pub mod panics;
pub(crate) mod problem;
mod router;
mod run;
mod stabilize;
mod state;
mod storage;
#[cfg(test)]
mod tests;
mod upload;
pub(crate) mod work;

pub use config::{Limits, ServeConfig, ServeError, ServiceError};
pub use listen::ListenConfig;
pub use live::LiveConfig;
pub use options::{JobOptions, OutputFormat};
pub use router::app;
pub use run::{init_logs, run, shutdown_signal, CONNECT_PATIENCE};
pub use state::AppState;
