//! Video input and output (being implemented).
use thiserror::Error;
#[derive(Debug, Error)]
pub enum VideoError {
    #[error("{0}")]
    Other(String),
}
