//! The picture's own motion in a clip stabilized in the camera.

use crate::error::TelemetryError;
use amc_core::gyro::GyroSamples;

/// The motion of the picture of a clip stabilized in the camera, where
/// the camera records it (GoPro's IORI, the image's orientation in the body,
/// beside CORI, the body's; telemetry-parser multiplies them per frame): the
/// body rate between consecutive orientations, stamped at their middle.
/// `None`: no in-camera stabilization recorded; an error where it is
/// recorded but the picture's orientation cannot be read (the body's gyro
/// would put back the shake the camera removed).
pub(crate) fn picture_motion(
    input: &telemetry_parser::Input,
) -> Result<Option<GyroSamples>, TelemetryError> {
    use telemetry_parser::tags_impl::{GetWithType, GroupId, TagId, TimeQuaternion};
    let Some(samples) = input.samples.as_ref() else {
        return Ok(None);
    };
    let stabilized = samples.iter().any(|s| {
        s.tag_map
            .as_ref()
            .is_some_and(|m| m.contains_key(&GroupId::ImageOrientation))
    });
    if !stabilized {
        return Ok(None);
    }
    let mut track: Vec<(f64, nalgebra::UnitQuaternion<f64>)> = Vec::new();
    for s in samples {
        let Some(map) = s.tag_map.as_ref().and_then(|m| m.get(&GroupId::Quaternion)) else {
            continue;
        };
        let Some(arr) = map.get_t(TagId::Data) as Option<&Vec<TimeQuaternion<f64>>> else {
            continue;
        };
        for q in arr {
            let t = q.t * 1e-3;
            let v = nalgebra::Quaternion::new(q.v.w, q.v.x, q.v.y, q.v.z);
            if t.is_finite() && v.norm() > 0.5 && track.last().is_none_or(|l| t > l.0) {
                track.push((t, nalgebra::UnitQuaternion::from_quaternion(v)));
            }
        }
    }
    if track.len() < 2 {
        return Err(TelemetryError::PictureUnreadable);
    }
    let mut out = GyroSamples::default();
    for pair in track.windows(2) {
        let ((t0, q0), (t1, q1)) = (pair[0], pair[1]);
        out.t.push(0.5 * (t0 + t1));
        out.w.push((q0.inverse() * q1).scaled_axis() / (t1 - t0));
    }
    Ok(Some(out))
}
