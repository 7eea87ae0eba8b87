//! Projection through a rolling shutter.
//!
//! A ray `z` in the mid-readout camera of a frame lands on the sensor row `y`
//! for which `y = pi_y(exp(-a(s(y))) z)` (`a(s) = s phi + ... + s^4 xi`, see
//! [`IntraFrame`]): the row it lands on is read at its own time. The map
//! `y -> pi_y(exp(-a(s(y))) z)` moves a row by about `|phi| f / H` per row of
//! change, well under 1 (a 10 deg readout rotation over 180 rows of a
//! 90 deg camera: 0.087), so fixed-point steps from the mid-readout guess
//! converge geometrically; steps stop once one moves the point by less than
//! [`FIXED_POINT_TOLERANCE_PX`], after at most [`FIXED_POINT_STEPS`].

use super::motion::{row_fraction, IntraFrame};
use crate::camera::CameraModel;
use crate::so3;
use nalgebra::{Matrix3, Vector2, Vector3};

/// Most fixed-point steps of [`project_rolling`] after the mid-readout guess.
pub const FIXED_POINT_STEPS: usize = 8;
/// A step that moves the point by less than this (pixels) ends the iteration.
pub const FIXED_POINT_TOLERANCE_PX: f64 = 1e-4;

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
        let q = cam.project(&(so3::exp(&(-intra.at(s))) * z))?;
        let done = (q - p).norm() < FIXED_POINT_TOLERANCE_PX;
        p = q;
        if done {
            break;
        }
    }
    Some(p)
}

/// [`project_rolling`] for many rays of one frame: the readout rotations
/// `exp(-a(s))` are tabulated once per sensor row (and interpolated
/// linearly between rows: the rotation changes by `|phi| / H` per row, so
/// the interpolation's error is that squared over eight, about 1e-9 rad for
/// a 10 deg turn over 180 rows), instead of three exponentials per ray.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RollingProjector {
    /// `exp(-a(s(y)))` for sensor rows `y = 0..=H` (empty: global shutter).
    rows: Vec<Matrix3<f64>>,
}

impl RollingProjector {
    /// True when the table is empty (a global shutter).
    pub fn is_global(&self) -> bool {
        self.rows.is_empty()
    }

    /// The largest readout rotation of any row, radians (0 for a global
    /// shutter): how far a ray can turn from its mid-readout direction.
    pub fn max_angle(&self) -> f64 {
        self.rows
            .iter()
            .map(|r| ((r.trace() - 1.0) * 0.5).clamp(-1.0, 1.0).acos())
            .fold(0.0, f64::max)
    }

    /// Tabulates `intra` for a sensor `height` rows high (nothing when it is
    /// zero). Reuses the table's memory.
    pub fn set(&mut self, intra: &IntraFrame, height: usize) {
        self.rows.clear();
        if intra.is_zero() {
            return;
        }
        self.rows.extend(
            (0..=height).map(|y| *so3::exp(&(-intra.at(row_fraction(y as f64, height)))).matrix()),
        );
    }

    /// The pixel of `cam` that sees the mid-readout ray `z` (see
    /// [`project_rolling`]). `cam` is the sensor's camera the table was set
    /// for, or the camera of a plane subsampled from it by an integer factor
    /// (a 4:2:0 chroma plane: its row `y` is sensor row `2 y + 1/2`).
    /// `guess`, a nearby ray's landing row, saves steps.
    pub fn project(
        &self,
        cam: &CameraModel,
        z: &Vector3<f64>,
        guess: Option<f64>,
    ) -> Option<Vector2<f64>> {
        self.project_within(cam, z, guess, FIXED_POINT_TOLERANCE_PX)
    }

    /// [`RollingProjector::project`], its steps ending once one moves the
    /// point by less than `tolerance_px` (which leaves it within about
    /// `kappa / (1 - kappa)` of that, `kappa` the iteration's contraction,
    /// under 0.1 for a 10 deg turn across a 90 deg camera's readout).
    pub fn project_within(
        &self,
        cam: &CameraModel,
        z: &Vector3<f64>,
        guess: Option<f64>,
        tolerance_px: f64,
    ) -> Option<Vector2<f64>> {
        if self.rows.is_empty() {
            return cam.project(z);
        }
        let last = (self.rows.len() - 1) as f64;
        let scale = last / cam.height.max(1) as f64;
        let offset = 0.5 * (scale - 1.0);
        // `exp(-a(s(y))) z`: the two nearest rows' rotations applied to `z`
        // and blended (a third of the work of blending the matrices first).
        // Past the first and last rows the blend goes on linearly, at the
        // path's slope there (up to a frame's height out), so that where a
        // ray lands is smooth across the frame's edges: a ray that lands out
        // there is not sampled either way, but a tabulated landing map
        // ([`super::LandingGrid`]) interpolates across the edges, and a path
        // held at its end rows would put a kink in it there.
        let turned = |y: f64| {
            let y = (y * scale + offset).clamp(-last, 2.0 * last);
            let i = (y.max(0.0) as usize).min(self.rows.len().saturating_sub(2));
            let a = y - i as f64;
            (self.rows[i] * z) * (1.0 - a) + (self.rows[i + 1] * z) * a
        };
        let mut p = match guess {
            Some(y) => cam.project(&turned(y))?,
            None => cam.project(z)?,
        };
        for _ in 0..FIXED_POINT_STEPS {
            let q = cam.project(&turned(p.y))?;
            let done = (q - p).norm() < tolerance_px;
            p = q;
            if done {
                break;
            }
        }
        Some(p)
    }
}
