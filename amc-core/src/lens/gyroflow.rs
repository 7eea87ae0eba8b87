//! Gyroflow lens profile (JSON): `calib_dimension: {w, h}` and
//! `fisheye_params: {camera_matrix: [[fx,0,cx],[0,fy,cy],[0,0,1]], distortion_coeffs: [k1..k4]}`
//! (OpenCV fisheye, the Gyroflow default `distortion_model`).

use super::value::{
    as_f64, as_size, fisheye_from, flat_numbers, get, intrinsics_from_k, invalid, show,
};
use super::LensError;
use crate::camera::CameraModel;
use serde_json::{Map, Value};

pub(super) fn parse_gyroflow(obj: &Map<String, Value>) -> Result<CameraModel, LensError> {
    const F: &str = "Gyroflow";
    if let Some(v) = obj.get("distortion_model") {
        match v {
            Value::Null => {}
            Value::String(s) if s.trim().is_empty() || s.trim() == "opencv_fisheye" => {}
            other => {
                return Err(LensError::UnsupportedModel {
                    key: "distortion_model".into(),
                    found: show(other),
                    supported: "opencv_fisheye (Gyroflow's default)",
                })
            }
        }
    }
    if let Some(v) = obj.get("digital_lens") {
        let none = v.is_null() || v.as_str().is_some_and(|s| s.trim().is_empty());
        if !none {
            return Err(LensError::UnsupportedModel {
                key: "digital_lens".into(),
                found: show(v),
                supported: "none (digital lens corrections such as SuperView are not supported)",
            });
        }
    }
    for key in ["input_horizontal_stretch", "input_vertical_stretch"] {
        if let Some(v) = obj.get(key).filter(|v| !v.is_null()) {
            let s = as_f64(v, key)?;
            if s != 1.0 {
                return Err(invalid(
                    key,
                    "1.0 (stretched/anamorphic inputs are not supported)",
                    v,
                ));
            }
        }
    }
    let dim = get(obj, "calib_dimension", "", F)?;
    let dim = dim
        .as_object()
        .ok_or_else(|| invalid("calib_dimension", "an object {\"w\": .., \"h\": ..}", dim))?;
    let width = as_size(get(dim, "w", "calib_dimension", F)?, "calib_dimension.w")?;
    let height = as_size(get(dim, "h", "calib_dimension", F)?, "calib_dimension.h")?;
    let fp = get(obj, "fisheye_params", "", F)?;
    let fp = fp
        .as_object()
        .ok_or_else(|| invalid("fisheye_params", "an object", fp))?;
    let k = intrinsics_from_k(
        get(fp, "camera_matrix", "fisheye_params", F)?,
        "fisheye_params.camera_matrix",
    )?;
    let dist_v = get(fp, "distortion_coeffs", "fisheye_params", F)?;
    let mut dist = Vec::new();
    flat_numbers(dist_v, "fisheye_params.distortion_coeffs", &mut dist)?;
    let distortion = fisheye_from(&dist, "fisheye_params.distortion_coeffs", dist_v)?;
    Ok(CameraModel::from_intrinsics(width, height, k, distortion))
}
