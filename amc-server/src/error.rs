//! Errors of the command line. `main` prints them as one line and exits non-zero.

use std::path::PathBuf;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum CliError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {msg}", path.display())]
    Image { path: PathBuf, msg: String },
    #[error(transparent)]
    Core(#[from] amc_core::AmcError),
    #[error(transparent)]
    Video(#[from] amc_video::VideoError),
    #[error(transparent)]
    Compare(#[from] crate::compare::CompareError),
    /// Bad command-line usage that clap cannot catch (a message a person can act on).
    #[error("{0}")]
    Usage(String),
    /// The run was cancelled (by its owner, or because its client went away).
    #[error("cancelled")]
    Cancelled,
    /// The run took longer than its time limit.
    #[error("stopped after the time limit of {secs:.0} s")]
    TimeLimit { secs: f64 },
}

impl CliError {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        CliError::Io {
            path: path.into(),
            source,
        }
    }
}
