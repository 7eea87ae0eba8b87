//! Projection through a rolling shutter.
//!
//! A ray `z` in the mid-readout camera of a frame lands on the sensor row `y`
//! for which `y = pi_y(exp(-a(s(y))) z)` (`a(s) = s phi + s^2 psi`, see
//! [`IntraFrame`]): the row it lands on is read at its own time. The map
//! `y -> pi_y(exp(-a(s(y))) z)` moves a row by about `|phi| f / H` per row of
//! change, well under 1 (a 10 deg readout rotation over 180 rows of a
//! 90 deg camera: 0.087), so fixed-point steps from the mid-readout guess
//! converge geometrically: after [`FIXED_POINT_STEPS`] the residual is that
//! ratio to the fourth power of the first step's move.

use super::motion::{row_fraction, IntraFrame};
use crate::camera::CameraModel;
use crate::so3;
use nalgebra::{Matrix3, Vector2, Vector3};

/// Fixed-point steps of [`project_rolling`] after the mid-readout guess.
pub const FIXED_POINT_STEPS: usize = 3;

/// The pixel of `cam` (a rolling-shutter sensor whose frame moves by `intra`
/// during its readout) that sees the ray `m ray`, with `m` the rotation from
/// the ray's frame into the frame's mid-readout camera. `None` when the ray
/// leaves the lens's field of view.
pub fn project_rolling(
    cam: &CameraModel,
    m: &Matrix3<f64>,
    intra: &IntraFrame,
    ray: &Vector3<f64>,
) -> Option<Vector2<f64>> {
    let z = m * ray;
    let mut p = cam.project(&z)?;
    if intra.is_zero() {
        return Some(p);
    }
    for _ in 0..FIXED_POINT_STEPS {
        let s = row_fraction(p.y, cam.height);
        let zs = so3::exp(&(-intra.at(s))) * z;
        p = cam.project(&zs)?;
    }
    Some(p)
}
