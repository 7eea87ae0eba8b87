//! Format detection: the one entry point, [`parse_lens_file`] (and
//! [`parse_lens`], its camera alone).

use super::document::parse_document;
use super::file::LensFile;
use super::gyroflow::parse_gyroflow;
use super::opencv::parse_opencv;
use super::project::parse_project;
use super::value::{as_f64, invalid, show};
use super::LensError;
use crate::camera::CameraModel;
use crate::shutter::MAX_READOUT_MS;
use serde_json::{Map, Value};

/// Parses a lens file in any supported format (project JSON, OpenCV JSON/YAML, Gyroflow) and validates it.
pub fn parse_lens(text: &str) -> Result<CameraModel, LensError> {
    parse_lens_file(text).map(|l| l.camera)
}

/// Reads the optional readout time at `key` (milliseconds, `0..=100`;
/// absent or `null`: `None`).
pub(super) fn readout_at(obj: &Map<String, Value>, key: &str) -> Result<Option<f64>, LensError> {
    match obj.get(key) {
        None | Some(Value::Null) => Ok(None),
        Some(v) => {
            let ms = as_f64(v, key)?;
            if (0.0..=MAX_READOUT_MS).contains(&ms) {
                Ok(Some(ms))
            } else {
                Err(invalid(
                    key,
                    "a readout time in milliseconds, 0..=100 (0 = global shutter; \
                     a bottom-to-top readout, given as a negative time, is not supported)",
                    v,
                ))
            }
        }
    }
}

/// Parses a lens file in any supported format with the readout time it states.
pub fn parse_lens_file(text: &str) -> Result<LensFile, LensError> {
    let root = parse_document(text)?;
    let obj = match &root {
        Value::Object(m) => m,
        Value::Null => return Err(LensError::Parse("the file is empty".into())),
        other => {
            return Err(LensError::Parse(format!(
                "expected a JSON object or YAML mapping at the top level, found {}",
                show(other)
            )))
        }
    };
    let (camera, readout_ms) =
        if obj.contains_key("calib_dimension") || obj.contains_key("fisheye_params") {
            (parse_gyroflow(obj)?, readout_at(obj, "frame_readout_time")?)
        } else if obj.contains_key("camera_matrix") || obj.contains_key("distortion_coefficients") {
            (parse_opencv(obj)?, None)
        } else if obj.contains_key("model") || obj.contains_key("fx") {
            (parse_project(obj)?, readout_at(obj, "readout_ms")?)
        } else {
            let mut keys: Vec<&str> = obj.keys().map(String::as_str).take(20).collect();
            if keys.is_empty() {
                keys.push("(none)");
            }
            return Err(LensError::UnknownFormat {
                found: keys.join(", "),
            });
        };
    camera.validate()?;
    Ok(LensFile { camera, readout_ms })
}
