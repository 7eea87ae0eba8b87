//! Lens files (contract only: being implemented).
use crate::camera::CameraModel;
use thiserror::Error;

#[derive(Debug, Error, Clone, PartialEq)]
pub enum LensError {
    #[error("lens file is not valid: {0}")]
    Parse(String),
}

pub fn parse_lens(_text: &str) -> Result<CameraModel, LensError> {
    Err(LensError::Parse("not implemented".into()))
}

pub fn to_project_json(_cam: &CameraModel) -> String { String::new() }
