//! The project's own JSON format (written by [`to_project_json`]):
//! ```text
//! {"model": "pinhole" | "opencv" | "fisheye", "width": 800, "height": 600,
//!  "fx": .., "fy": .., "cx": .., "cy": .., "skew": 0.0 (optional), "dist": [..],
//!  "readout_ms": 0.0 (optional)}
//! ```
//! `readout_ms`: the rolling-shutter readout time, first row to last,
//! milliseconds, `0..=100` (0 = global shutter); absent when not known.
//! `dist`: pinhole -> empty, absent or all zeros; opencv -> `k1 k2 p1 p2 [k3]`;
//! fisheye -> `k1 k2 k3 k4`.

use super::file::LensFile;
use super::value::{as_f64, as_size, fisheye_from, flat_numbers, get, invalid, radtan_from, show};
use super::LensError;
use crate::camera::{CameraModel, Distortion};
use serde_json::{Map, Value};

/// Writes `cam` in the project JSON format; [`parse_lens`](super::parse_lens) reads it back unchanged.
/// Non-finite numbers are written as `null` (and rejected when read back).
pub fn to_project_json(cam: &CameraModel) -> String {
    LensFile {
        camera: cam.clone(),
        readout_ms: None,
    }
    .to_project_json()
}

impl LensFile {
    /// Writes the camera and the readout (when known) in the project JSON
    /// format; [`parse_lens_file`](super::parse_lens_file) reads it back unchanged.
    pub fn to_project_json(&self) -> String {
        let readout = self
            .readout_ms
            .map(|ms| format!(",\n  \"readout_ms\": {}", num(ms)))
            .unwrap_or_default();
        camera_json(&self.camera, &readout)
    }
}

/// The project JSON of `cam`, with `extra` (`,\n  "key": value` lines) before the closing brace.
fn camera_json(cam: &CameraModel, extra: &str) -> String {
    let (model, dist): (&str, Vec<f64>) = match cam.distortion {
        Distortion::None => ("pinhole", vec![]),
        Distortion::RadTan { k1, k2, p1, p2, k3 } => ("opencv", vec![k1, k2, p1, p2, k3]),
        Distortion::Fisheye { k1, k2, k3, k4 } => ("fisheye", vec![k1, k2, k3, k4]),
    };
    let dist: Vec<String> = dist.into_iter().map(num).collect();
    format!(
        "{{\n  \"model\": \"{model}\",\n  \"width\": {},\n  \"height\": {},\n  \"fx\": {},\n  \"fy\": {},\n  \
         \"cx\": {},\n  \"cy\": {},\n  \"skew\": {},\n  \"dist\": [{}]{extra}\n}}\n",
        cam.width,
        cam.height,
        num(cam.fx),
        num(cam.fy),
        num(cam.cx),
        num(cam.cy),
        num(cam.skew),
        dist.join(", ")
    )
}

/// Shortest round-trip representation of a float as a JSON number (`null` if not finite).
fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:?}")
    } else {
        "null".into()
    }
}

pub(super) fn parse_project(obj: &Map<String, Value>) -> Result<CameraModel, LensError> {
    const F: &str = "project";
    let model_v = get(obj, "model", "", F)?;
    let model = model_v
        .as_str()
        .ok_or_else(|| invalid("model", "\"pinhole\", \"opencv\" or \"fisheye\"", model_v))?;
    let num = |k: &str| get(obj, k, "", F).and_then(|v| as_f64(v, k));
    let width = as_size(get(obj, "width", "", F)?, "width")?;
    let height = as_size(get(obj, "height", "", F)?, "height")?;
    let (fx, fy, cx, cy) = (num("fx")?, num("fy")?, num("cx")?, num("cy")?);
    let skew = match obj.get("skew") {
        None | Some(Value::Null) => 0.0,
        Some(v) => as_f64(v, "skew")?,
    };
    let mut dist = Vec::new();
    let dist_v = obj.get("dist").unwrap_or(&Value::Null);
    match dist_v {
        Value::Null => {}
        Value::Array(_) => flat_numbers(dist_v, "dist", &mut dist)?,
        other => return Err(invalid("dist", "a list of distortion coefficients", other)),
    }
    let distortion = match model.trim().to_ascii_lowercase().as_str() {
        "pinhole" | "none" => {
            if dist.iter().any(|&c| c != 0.0) {
                return Err(invalid(
                    "dist",
                    "empty (or all zeros) for model \"pinhole\"; use model \"opencv\" or \"fisheye\" for a distorted lens",
                    dist_v,
                ));
            }
            Distortion::None
        }
        "opencv" | "radtan" => {
            if dist_v.is_null() {
                return Err(LensError::MissingKey {
                    format: F,
                    key: "dist (k1 k2 p1 p2 [k3])".into(),
                });
            }
            match dist.len() {
                4 | 5 => radtan_from(&dist, "dist", dist_v)?,
                n => {
                    return Err(invalid(
                        "dist",
                        format!(
                            "4 or 5 coefficients k1 k2 p1 p2 [k3] for model \"opencv\", got {n}"
                        ),
                        dist_v,
                    ))
                }
            }
        }
        "fisheye" => {
            if dist_v.is_null() {
                return Err(LensError::MissingKey {
                    format: F,
                    key: "dist (k1 k2 k3 k4)".into(),
                });
            }
            fisheye_from(&dist, "dist", dist_v)?
        }
        _ => {
            return Err(LensError::UnsupportedModel {
                key: "model".into(),
                found: show(model_v),
                supported: "\"pinhole\", \"opencv\", \"fisheye\"",
            })
        }
    };
    Ok(CameraModel::from_intrinsics(
        width,
        height,
        [fx, fy, cx, cy, skew],
        distortion,
    ))
}
