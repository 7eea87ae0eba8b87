//! # amc-gyrolog
//!
//! A gyro log from its bytes, for the engine (a file on disk) and the page
//! (a clip the browser holds) alike: a camera's own IMU track (GoPro GPMF,
//! Sony, DJI, Insta360), a flight controller's blackbox, Gyroflow's `.gcsv`,
//! phone-app logs, all read by the `telemetry-parser` crate ([`read_gyro_stream`],
//! [`read_gyro_bytes`]); then synchronized with a run's own motion
//! ([`sync_log`], reported as [`GyroReport`]) and fused with its tracking
//! into each frame's pose ([`fuse_log`]); where the camera records no
//! readout, it is measured against the log ([`measure_readout`]). No file system, no threads: it
//! builds for `wasm32-unknown-unknown`.

#![deny(missing_docs)]

mod error;
mod fuse;
mod log;
mod mp4_guard;
mod parse;
mod picture;
mod readout;
mod report;

pub use error::{GyroLogError, TelemetryError};
pub use fuse::{fuse_log, video_only_warning, FuseLogError, FusedLog};
pub use log::GyroLog;
pub use parse::{read_gyro_bytes, read_gyro_stream};
pub use readout::measure_readout;
pub use report::{sync_log, GyroReport, ReadoutReport};
