//! Why a gyro log cannot be read or used.

use amc_core::gyro;
use std::path::PathBuf;
use thiserror::Error;

/// Why a gyro log cannot be used.
#[derive(Debug, Error)]
#[allow(missing_docs)] // Each variant's message says what its fields are.
pub enum GyroLogError {
    /// The file cannot be read.
    #[error("cannot read the gyro log {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    /// No format it knows.
    #[error("{path} is no gyro log telemetry-parser knows (GoPro, Sony, DJI, Insta360, Betaflight, ArduPilot, Gyroflow .gcsv, phone apps) nor a CSV of a time and three rates: {why}")]
    Unknown { path: PathBuf, why: String },
    /// A known format without gyroscope samples.
    #[error("{path} holds no gyroscope samples")]
    NoGyro { path: PathBuf },
    /// The log does not fit the video.
    #[error("cannot synchronize the gyro log {source_name} with the video: {error}")]
    Sync {
        source_name: String,
        error: gyro::GyroError,
    },
}

/// Why telemetry-parser gives no log from a file.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum TelemetryError {
    /// Not a format it knows, or a damaged one (its own words).
    #[error("{0}")]
    Parser(String),
    /// It panicked on the file (caught where panics unwind: not in wasm32,
    /// where they abort).
    #[error("the telemetry parser failed on this file")]
    Panicked,
    /// Stabilized in the camera (GoPro's IORI) but the picture's own
    /// orientation is not there.
    #[error(
        "the clip was stabilized in the camera (IORI) but the picture's orientation \
         cannot be read from it: its gyro is the body's motion, not the picture's"
    )]
    PictureUnreadable,
}
