//! Errors of a run.

use amc_core::AmcError;
use amc_video::VideoError;
use std::path::PathBuf;
use thiserror::Error;

/// Everything that can stop a run. Callers choose what to do by variant (the
/// service maps them to HTTP statuses), never by message text.
#[derive(Debug, Error)]
pub enum RunError {
    /// Reading the input or writing an output failed.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// The stabilizer refused a parameter or a frame.
    #[error(transparent)]
    Core(#[from] AmcError),
    /// A lens file could not be read.
    #[error("{}: cannot read the lens file: {source}", path.display())]
    LensRead {
        /// The lens file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A lens file is not a calibration we understand.
    #[error("{}: {source}", path.display())]
    LensParse {
        /// The lens file (or `the lens file` for one sent as text).
        path: PathBuf,
        /// What is wrong with it.
        source: amc_core::lens::LensError,
    },
    /// The input decoded to no frames.
    #[error("{}: no frames could be read", path.display())]
    NoFrames {
        /// The input.
        path: PathBuf,
    },
    /// Two paths of one run name the same file: writing one would destroy the other.
    #[error(
        "{} ({first}) and {} ({second}) are the same file; writing the {second} would destroy the {first}: choose another path",
        first_path.display(), second_path.display()
    )]
    SamePath {
        /// What the first path is (`input`, `output`, `telemetry`, `metrics`).
        first: &'static str,
        /// Its path as given.
        first_path: PathBuf,
        /// What the second path is.
        second: &'static str,
        /// Its path as given.
        second_path: PathBuf,
    },
    /// Writing the telemetry failed.
    #[error("{}: cannot write: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The run was cancelled (by its owner, a signal, or a client going away).
    #[error("cancelled")]
    Cancelled,
    /// The run took longer than its time limit.
    #[error("stopped after the time limit of {secs:.0} s")]
    TimeLimit {
        /// The limit, seconds.
        secs: f64,
    },
    /// A decoder or encoder thread died (a bug: their failures are errors of their own).
    #[error("internal error: the {stage} thread failed")]
    ThreadFailed {
        /// `decoder` or `encoder`.
        stage: &'static str,
    },
    /// The render threads could not be started (the system refused them).
    #[error("cannot start the render threads: {0}")]
    Threads(String),
    /// The metrics thread died (a bug: it has no failure of its own).
    #[error("internal error: the metrics worker failed")]
    MetricsWorker,
}
