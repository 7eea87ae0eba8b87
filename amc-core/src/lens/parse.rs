//! Format detection: the one entry point, [`parse_lens`].

use super::document::parse_document;
use super::gyroflow::parse_gyroflow;
use super::opencv::parse_opencv;
use super::project::parse_project;
use super::value::show;
use super::LensError;
use crate::camera::CameraModel;
use serde_json::Value;

/// Parses a lens file in any supported format (project JSON, OpenCV JSON/YAML, Gyroflow) and validates it.
pub fn parse_lens(text: &str) -> Result<CameraModel, LensError> {
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
    let cam = if obj.contains_key("calib_dimension") || obj.contains_key("fisheye_params") {
        parse_gyroflow(obj)?
    } else if obj.contains_key("camera_matrix") || obj.contains_key("distortion_coefficients") {
        parse_opencv(obj)?
    } else if obj.contains_key("model") || obj.contains_key("fx") {
        parse_project(obj)?
    } else {
        let mut keys: Vec<&str> = obj.keys().map(String::as_str).take(20).collect();
        if keys.is_empty() {
            keys.push("(none)");
        }
        return Err(LensError::UnknownFormat {
            found: keys.join(", "),
        });
    };
    cam.validate()?;
    Ok(cam)
}
