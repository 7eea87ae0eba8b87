//! Lens files: parsing calibrations into a [`CameraModel`](crate::camera::CameraModel)
//! and writing the project format.
//!
//! [`parse_lens`] detects the format from the content (`parse.rs`) and reads it with one
//! file per format, each documenting its keys: the project's own JSON (`project.rs`,
//! written by [`to_project_json`]), OpenCV calibrations in JSON or YAML (`opencv.rs`) and
//! Gyroflow lens profiles (`gyroflow.rs`). `document.rs` turns the text (JSON or
//! OpenCV-flavoured YAML) into one JSON value; `value.rs` reads typed, checked values out
//! of it. The resulting model is checked with
//! [`CameraModel::validate`](crate::camera::CameraModel::validate). Every error names the
//! key and what was expected, so a person can fix the file.
//!
//! A file may also state the sensor's rolling-shutter readout time
//! ([`parse_lens_file`], [`LensFile::readout_ms`]): the project JSON's optional
//! `readout_ms`, a Gyroflow profile's `frame_readout_time` (both milliseconds,
//! `0..=100`).

mod document;
mod error;
mod file;
mod gyroflow;
mod opencv;
mod parse;
mod project;
#[cfg(test)]
mod tests;
mod value;

pub use error::LensError;
pub use file::LensFile;
pub use parse::{parse_lens, parse_lens_file};
pub use project::to_project_json;
