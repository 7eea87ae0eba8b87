//! Fisheye (`Distortion::Fisheye`, OpenCV `cv::fisheye::projectPoints`, Kannala-Brandt),
//! with `theta` the angle between the ray and the optical axis (`atan2(sqrt(X^2+Y^2), Z)`,
//! so rays with `Z <= 0`, beyond 90 degrees, are allowed):
//! ```text
//! theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
//! xd = theta_d * X / sqrt(X^2 + Y^2),  yd = theta_d * Y / sqrt(X^2 + Y^2)
//! ```
//! Valid for `theta < theta_max = min(pi, first positive root of
//! 1 + 3 k1 t + 5 k2 t^2 + 7 k3 t^3 + 9 k4 t^4 in t = theta^2)`.
//! For `Z > 0` this is identical to OpenCV, which writes `theta = atan(r)`.
//!
//! The inverse is a safeguarded 1-D Newton iteration on `theta`; pixels beyond
//! `theta_max` and solutions that fail to converge are rejected.

use super::model::{check_size, CameraError, CameraModel, Distortion};
use super::poly::{first_positive_root, invert_odd_poly, monotone_on, poly_eval, MAX_NEWTON};
use std::f64::consts::PI;

impl CameraModel {
    /// A square-pixel fisheye (Kannala-Brandt, coefficients `k`) whose horizontal field
    /// of view across the full width is `hfov_deg` (may exceed 180), principal point at the
    /// image centre: `f = (w/2) / theta_d(hfov/2)`.
    pub fn fisheye_hfov(
        width: usize,
        height: usize,
        hfov_deg: f64,
        k: [f64; 4],
    ) -> Result<Self, CameraError> {
        check_size(width, height)?;
        if k.iter().any(|c| !c.is_finite()) {
            return Err(CameraError::invalid(
                "fisheye coefficients",
                format!("{k:?}"),
                "finite numbers",
            ));
        }
        if !(hfov_deg.is_finite() && hfov_deg > 0.0 && hfov_deg < 360.0) {
            return Err(CameraError::invalid(
                "hfov_deg",
                hfov_deg,
                "(0, 360) degrees",
            ));
        }
        let theta = hfov_deg.to_radians() / 2.0;
        let distortion = Distortion::Fisheye {
            k1: k[0],
            k2: k[1],
            k3: k[2],
            k4: k[3],
        };
        if !(theta < fisheye_theta_limit(&k)) {
            return Err(CameraError::invalid(
                "hfov_deg",
                hfov_deg,
                "below twice the angle at which the fisheye polynomial theta_d(theta) stops increasing",
            ));
        }
        let theta_d = theta * poly_eval(&odd_coeffs_fisheye(&k), theta * theta);
        let f = (width as f64 / 2.0) / theta_d;
        let cam = Self {
            width,
            height,
            fx: f,
            fy: f,
            cx: (width as f64 - 1.0) / 2.0,
            cy: (height as f64 - 1.0) / 2.0,
            skew: 0.0,
            distortion,
        };
        cam.validate()?;
        Ok(cam)
    }
}

/// Ray -> distorted normalized coordinates, or `None` outside the valid domain.
#[inline]
pub(super) fn distort(k: &[f64; 4], x: f64, y: f64, z: f64) -> Option<(f64, f64)> {
    let rxy = (x * x + y * y).sqrt();
    if !(rxy.is_finite() && z.is_finite()) {
        return None;
    }
    if rxy == 0.0 {
        // On the optical axis: forward is the principal point, backward is theta = pi.
        return (z > 0.0).then_some((0.0, 0.0));
    }
    let theta = rxy.atan2(z);
    let t = theta * theta;
    if !(theta < PI) || !monotone_on(&deriv_coeffs_fisheye(k), t) {
        return None;
    }
    let scale = theta * poly_eval(&odd_coeffs_fisheye(k), t) / rxy;
    Some((x * scale, y * scale))
}

/// Inverts the fisheye map `theta_d(theta)` for `theta` in `[0, theta_max)`.
pub(super) fn undistort_fisheye(k: &[f64; 4], theta_d: f64) -> Option<f64> {
    let pcoef = odd_coeffs_fisheye(k);
    let dcoef = deriv_coeffs_fisheye(k);
    // Fast path: plain Newton from theta = theta_d.
    let mut th = theta_d.min(3.0);
    for _ in 0..MAX_NEWTON {
        let t = th * th;
        let g = th * poly_eval(&pcoef, t) - theta_d;
        let dg = poly_eval(&dcoef, t);
        if !(dg > 0.0) || !g.is_finite() {
            break;
        }
        let step = g / dg;
        th -= step;
        if step.abs() <= 1e-15 * (1.0 + th.abs()) {
            break;
        }
    }
    let t = th * th;
    if (0.0..PI).contains(&th)
        && (th * poly_eval(&pcoef, t) - theta_d).abs() <= 1e-12 * (1.0 + theta_d)
        && monotone_on(&dcoef, t)
    {
        return Some(th);
    }
    // Robust path: bracketed solve inside the monotone range.
    invert_odd_poly(&pcoef, &dcoef, theta_d, fisheye_theta_limit(k))
}

/// `1 + k1 t + k2 t^2 + k3 t^3 + k4 t^4`, so `theta_d = theta * P(theta^2)`.
#[inline]
pub(super) fn odd_coeffs_fisheye(k: &[f64; 4]) -> [f64; 5] {
    [1.0, k[0], k[1], k[2], k[3]]
}

/// `1 + 3 k1 t + 5 k2 t^2 + 7 k3 t^3 + 9 k4 t^4 = d theta_d / d theta`.
#[inline]
pub(super) fn deriv_coeffs_fisheye(k: &[f64; 4]) -> [f64; 5] {
    [1.0, 3.0 * k[0], 5.0 * k[1], 7.0 * k[2], 9.0 * k[3]]
}

/// `theta_max = min(pi, first theta at which theta_d(theta) stops increasing)`.
pub(super) fn fisheye_theta_limit(k: &[f64; 4]) -> f64 {
    match first_positive_root(&deriv_coeffs_fisheye(k), PI * PI) {
        Some(t) => t.sqrt().min(PI),
        None => PI,
    }
}
