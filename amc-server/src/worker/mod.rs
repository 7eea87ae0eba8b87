//! `amc worker`: runs the jobs that `amc serve --queue --store` replicas
//! accept. Any number of workers on any number of machines share one job
//! table and bucket; each runs one job at a time (size a machine with one
//! worker of `--threads` = its cores, or several single-threaded ones).
//!
//! A worker claims the oldest waiting job, downloads its upload, runs the
//! same pipeline as `amc stabilize` (`serve::work::stabilize`), renews its
//! lease and writes its progress twice a second, uploads the output and
//! telemetry and marks the job done or failed with the reason ([`job`]).
//! A job cancelled by `DELETE` is stopped within a second. On SIGTERM or
//! Ctrl-C it stops claiming, stops its running job and hands it back to
//! the queue (not counted as an attempt), then exits 0. It serves
//! `/healthz` and `/metrics` on `--addr` ([`http`]), and sweeps expired
//! jobs like the replicas do.

mod config;
mod http;
mod job;
mod run;
mod scratch;
mod state;

pub use config::{WorkerConfig, WorkerError};
pub use run::run;
