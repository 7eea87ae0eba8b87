//! `amc_server`: the HTTP service behind `amc serve` and `amc worker`.
//!
//! [`serve`] is the axum service (REST jobs, the live WebSocket feed, the
//! page); [`worker`] runs queued jobs in cluster mode; [`cluster`] is the job
//! store in PostgreSQL with videos in S3; [`auth`] is who may ask what. Runs go through `amc-engine`; the
//! command line (`amc-cli`) is the only place clap lives. See
//! `docs/ARCHITECTURE.md`.

pub mod auth;
pub mod cluster;
pub mod poison;
pub mod serve;
pub mod setting;
pub mod worker;
