//! Errors of `amc compare`.

use super::config::MAX_LOOKAHEAD;
use crate::gt::GtError;
use crate::plot::PlotError;
use crate::synth::SynthError;
use amc_core::AmcError;
use amc_engine::RunError;
use amc_video::VideoError;
use std::path::PathBuf;
use thiserror::Error;

/// Errors of `amc compare` that are not video or stabilizer errors.
#[derive(Debug, Error)]
pub enum CompareError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot run {what}: {source}")]
    Spawn {
        what: String,
        source: std::io::Error,
    },
    #[error("{what} failed: {detail}")]
    ChildFailed { what: String, detail: String },
    #[error("{what} ran longer than {seconds} s (allowed: --timeout SECS)")]
    Timeout { what: String, seconds: u64 },
    #[error("nothing to compare: give one or more CLIP paths or --synthetic")]
    NoClips,
    #[error("invalid --synthetic-seconds {0} (allowed: 0.5 to 60 seconds)")]
    SyntheticSeconds(f64),
    #[error("invalid --lookahead {0} (allowed: 1 to {MAX_LOOKAHEAD} frames)")]
    Lookahead(usize),
    #[error("invalid --repeat {0} (allowed: 1 to 10 runs)")]
    Repeat(usize),
    #[error("{}: the panorama for --synthetic does not exist (pass --panorama FILE)", .0.display())]
    NoPanorama(PathBuf),
    #[error("{method} on {clip}: produced no frames")]
    NoOutput { method: String, clip: String },
    #[error("internal error: {0}")]
    Internal(String),
    /// A clip decoded to no frames.
    #[error("{}: no frames could be read", .0.display())]
    NoFrames(PathBuf),
    /// A clip's `lens.json` is not a calibration we understand.
    #[error("{}: {source}", path.display())]
    Lens {
        /// The lens file.
        path: PathBuf,
        /// What is wrong with it.
        source: amc_core::lens::LensError,
    },
    /// A figure or image could not be encoded.
    #[error("{}: {detail}", path.display())]
    Image {
        /// The file.
        path: PathBuf,
        /// What failed.
        detail: String,
    },
    /// A run of ours failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// Reading a clip or writing a file failed.
    #[error(transparent)]
    Video(#[from] VideoError),
    /// The stabilizer refused a parameter or a frame.
    #[error(transparent)]
    Core(#[from] AmcError),
    /// A synthetic sequence could not be rendered.
    #[error(transparent)]
    Synth(#[from] SynthError),
    /// A plot could not be written.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// A ground truth could not be read.
    #[error(transparent)]
    Gt(#[from] GtError),
}

impl CompareError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        CompareError::Io {
            path: path.into(),
            source,
        }
    }
}
