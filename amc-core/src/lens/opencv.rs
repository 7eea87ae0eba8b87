//! OpenCV calibration, JSON or YAML as written by `cv::FileStorage` (the `%YAML:1.0`
//! header and `!!opencv-matrix` tags are accepted): `camera_matrix` (`{rows, cols, dt, data}`
//! or a nested 3x3 array) with `K = [[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`,
//! `distortion_coefficients` (4 or 5 values `k1 k2 p1 p2 [k3]`, or 4 values `k1..k4` when
//! `distortion_model` is `fisheye`/`equidistant` or `fisheye: true`), and the image size as
//! `image_width`/`image_height`, `width`/`height` or `image_size: [w, h]`.

use super::value::{
    as_size, fisheye_from, flat_numbers, get, intrinsics_from_k, invalid, radtan_from, read_matrix,
};
use super::LensError;
use crate::camera::{CameraModel, Distortion};
use serde_json::{Map, Value};

pub(super) fn parse_opencv(obj: &Map<String, Value>) -> Result<CameraModel, LensError> {
    const F: &str = "OpenCV";
    let k = intrinsics_from_k(get(obj, "camera_matrix", "", F)?, "camera_matrix")?;
    let (width, height) = opencv_image_size(obj)?;
    let dist_v = get(obj, "distortion_coefficients", "", F)?;
    let dist = read_matrix(dist_v, "distortion_coefficients")?;
    let fisheye_flag = match obj.get("fisheye") {
        None | Some(Value::Null) => false,
        Some(Value::Bool(b)) => *b,
        Some(v) if v.as_i64().is_some() => v.as_i64() != Some(0),
        Some(v) => return Err(invalid("fisheye", "true or false", v)),
    };
    let model = match obj.get("distortion_model") {
        None | Some(Value::Null) => String::new(),
        Some(Value::String(s)) => s.trim().to_ascii_lowercase(),
        Some(v) => {
            return Err(invalid(
                "distortion_model",
                "a string such as \"plumb_bob\" or \"fisheye\"",
                v,
            ))
        }
    };
    let is_fisheye =
        fisheye_flag
            || match model.as_str() {
                "fisheye" | "equidistant" | "kannala_brandt" | "kannala-brandt"
                | "opencv_fisheye" => true,
                ""
                | "plumb_bob"
                | "radtan"
                | "radial-tangential"
                | "radial_tangential"
                | "opencv"
                | "pinhole"
                | "rational_polynomial" => false,
                other => return Err(LensError::UnsupportedModel {
                    key: "distortion_model".into(),
                    found: format!("\"{other}\""),
                    supported:
                        "plumb_bob / radtan (k1 k2 p1 p2 [k3]) or fisheye / equidistant (k1..k4)",
                }),
            };
    let distortion = if is_fisheye {
        fisheye_from(&dist, "distortion_coefficients", dist_v)?
    } else if dist.is_empty() {
        Distortion::None
    } else {
        radtan_from(&dist, "distortion_coefficients", dist_v)?
    };
    Ok(CameraModel::from_intrinsics(width, height, k, distortion))
}

fn opencv_image_size(obj: &Map<String, Value>) -> Result<(usize, usize), LensError> {
    for (wk, hk) in [("image_width", "image_height"), ("width", "height")] {
        match (obj.get(wk), obj.get(hk)) {
            (Some(w), Some(h)) => return Ok((as_size(w, wk)?, as_size(h, hk)?)),
            (Some(_), None) => {
                return Err(LensError::MissingKey {
                    format: "OpenCV",
                    key: hk.into(),
                })
            }
            (None, Some(_)) => {
                return Err(LensError::MissingKey {
                    format: "OpenCV",
                    key: wk.into(),
                })
            }
            (None, None) => {}
        }
    }
    if let Some(v) = obj.get("image_size") {
        let mut wh = Vec::new();
        let parsed = match v {
            Value::Object(m) => match (
                m.get("width").or(m.get("w")),
                m.get("height").or(m.get("h")),
            ) {
                (Some(w), Some(h)) => Some((
                    as_size(w, "image_size.width")?,
                    as_size(h, "image_size.height")?,
                )),
                _ => None,
            },
            Value::Array(_) => {
                flat_numbers(v, "image_size", &mut wh)?;
                None
            }
            _ => None,
        };
        if let Some(p) = parsed {
            return Ok(p);
        }
        if let [w, h] = wh[..] {
            return Ok((
                as_size(&Value::from(w), "image_size[0]")?,
                as_size(&Value::from(h), "image_size[1]")?,
            ));
        }
        return Err(invalid("image_size", "[width, height]", v));
    }
    Err(LensError::MissingImageSize)
}
