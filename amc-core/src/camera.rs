//! Camera models: pinhole, OpenCV radial-tangential and OpenCV fisheye (Kannala-Brandt).
//!
//! Conventions: camera frame x right, y down, z forward; pixel centres at integer
//! coordinates (OpenCV), so the image spans `[-0.5, width - 0.5] x [-0.5, height - 0.5]`.
//!
//! Every model maps a ray `(X, Y, Z)` (any positive scale) to *distorted normalized
//! coordinates* `(xd, yd)` and then to pixels with the intrinsics (`skew` in pixels):
//! ```text
//! u = fx * xd + skew * yd + cx
//! v =            fy * yd + cy
//! ```
//!
//! **Pinhole** (`Distortion::None`), valid for `Z > eps * |ray|`:
//! ```text
//! xd = X / Z,  yd = Y / Z
//! ```
//!
//! **Radial-tangential** (`Distortion::RadTan`, OpenCV `projectPoints` with 5 coefficients),
//! with `x = X/Z, y = Y/Z, r^2 = x^2 + y^2`:
//! ```text
//! radial = 1 + k1 r^2 + k2 r^4 + k3 r^6
//! xd = x * radial + 2 p1 x y + p2 (r^2 + 2 x^2)
//! yd = y * radial + p1 (r^2 + 2 y^2) + 2 p2 x y
//! ```
//! Valid for `Z > eps * |ray|` and `r < r_max`, where `r_max` is the first radius at which
//! the radial map `r (1 + k1 r^2 + k2 r^4 + k3 r^6)` stops increasing, i.e. the first
//! positive root of `1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3` in `s = r^2` (infinite if none).
//! Beyond it the polynomial folds back and the model is meaningless.
//!
//! **Fisheye** (`Distortion::Fisheye`, OpenCV `cv::fisheye::projectPoints`, Kannala-Brandt),
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
//! **Inverse** (`unproject`): radial-tangential uses a damped 2-D Newton iteration
//! (falling back to a bracketed 1-D radial solve for the starting point under strong
//! distortion); fisheye uses a safeguarded 1-D Newton iteration on `theta`. Both reject
//! pixels outside the invertible domain (beyond `r_max` / `theta_max`) and solutions
//! that fail to converge.
//!
//! The validity limits are decided exactly but cheaply: a one-line sufficient bound
//! (sum of the negative terms of the derivative polynomial) settles almost every call;
//! only rays near the limit run the exact root isolation, which allocates nothing.

// Negated float comparisons (`!(x > 0.0)`) are deliberate throughout: they also reject NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use nalgebra::{Matrix3, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use thiserror::Error;

/// An invalid camera parameter. Names the field, the offending value and what is allowed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CameraError {
    /// A parameter is outside its allowed range.
    #[error("invalid camera {name}: {value} (allowed: {allowed})")]
    Invalid {
        /// Name of the field or argument.
        name: &'static str,
        /// The offending value, formatted (with context where useful).
        value: String,
        /// Human-readable allowed range.
        allowed: &'static str,
    },
}

impl CameraError {
    fn invalid(name: &'static str, value: impl std::fmt::Display, allowed: &'static str) -> Self {
        CameraError::Invalid {
            name,
            value: value.to_string(),
            allowed,
        }
    }
}

/// Lens distortion model (see the module documentation for the equations).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "lowercase")]
pub enum Distortion {
    /// Ideal pinhole, no distortion.
    None,
    /// OpenCV radial-tangential model with the 5 coefficients `k1 k2 p1 p2 k3`.
    RadTan {
        /// Radial coefficient of `r^2`.
        k1: f64,
        /// Radial coefficient of `r^4`.
        k2: f64,
        /// First tangential coefficient.
        p1: f64,
        /// Second tangential coefficient.
        p2: f64,
        /// Radial coefficient of `r^6`.
        k3: f64,
    },
    /// OpenCV fisheye (Kannala-Brandt) model with coefficients `k1..k4`.
    Fisheye {
        /// Coefficient of `theta^3`.
        k1: f64,
        /// Coefficient of `theta^5`.
        k2: f64,
        /// Coefficient of `theta^7`.
        k3: f64,
        /// Coefficient of `theta^9`.
        k4: f64,
    },
}

/// A calibrated camera: image size, intrinsics and distortion.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    /// Image width in pixels (the calibration resolution).
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Horizontal focal length in pixels.
    pub fx: f64,
    /// Vertical focal length in pixels.
    pub fy: f64,
    /// Principal point x in pixels (pixel centres at integers).
    pub cx: f64,
    /// Principal point y in pixels.
    pub cy: f64,
    /// Skew in pixels: `u = fx * xd + skew * yd + cx`.
    pub skew: f64,
    /// Distortion model.
    pub distortion: Distortion,
}

/// Relative bound on `Z / |ray|` below which pinhole and radtan rays are rejected.
const Z_EPS: f64 = 1e-9;
/// Maximum Newton iterations of the inverse maps.
const MAX_NEWTON: usize = 50;

impl CameraModel {
    /// An undistorted pinhole camera.
    pub fn pinhole(width: usize, height: usize, fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            skew: 0.0,
            distortion: Distortion::None,
        }
    }

    /// A square-pixel pinhole camera with horizontal field of view `hfov_deg` across the
    /// full width (edge to edge) and the principal point at the image centre
    /// `((w-1)/2, (h-1)/2)`: `fx = fy = (w/2) / tan(hfov/2)`.
    pub fn pinhole_hfov(width: usize, height: usize, hfov_deg: f64) -> Result<Self, CameraError> {
        check_size(width, height)?;
        if !(hfov_deg.is_finite() && hfov_deg > 0.0 && hfov_deg <= 179.0) {
            return Err(CameraError::invalid(
                "hfov_deg",
                hfov_deg,
                "(0, 179] degrees",
            ));
        }
        let fx = (width as f64 / 2.0) / (hfov_deg.to_radians() / 2.0).tan();
        let cam = Self::pinhole(
            width,
            height,
            fx,
            fx,
            (width as f64 - 1.0) / 2.0,
            (height as f64 - 1.0) / 2.0,
        );
        cam.validate()?;
        Ok(cam)
    }

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

    /// Checks every parameter: sizes >= 1, finite positive `fx`, `fy`, finite `cx`, `cy`,
    /// `skew` and distortion coefficients, and the principal point within
    /// `[-width, 2*width] x [-height, 2*height]`.
    pub fn validate(&self) -> Result<(), CameraError> {
        check_size(self.width, self.height)?;
        let (w, h) = (self.width as f64, self.height as f64);
        if !(self.fx.is_finite() && self.fx > 0.0) {
            return Err(CameraError::invalid(
                "fx",
                self.fx,
                "a finite number > 0 (pixels)",
            ));
        }
        if !(self.fy.is_finite() && self.fy > 0.0) {
            return Err(CameraError::invalid(
                "fy",
                self.fy,
                "a finite number > 0 (pixels)",
            ));
        }
        if !(self.cx.is_finite() && self.cx >= -w && self.cx <= 2.0 * w) {
            return Err(CameraError::invalid(
                "cx",
                format!("{} (image width {})", self.cx, self.width),
                "[-width, 2*width] pixels",
            ));
        }
        if !(self.cy.is_finite() && self.cy >= -h && self.cy <= 2.0 * h) {
            return Err(CameraError::invalid(
                "cy",
                format!("{} (image height {})", self.cy, self.height),
                "[-height, 2*height] pixels",
            ));
        }
        if !self.skew.is_finite() {
            return Err(CameraError::invalid(
                "skew",
                self.skew,
                "a finite number (pixels)",
            ));
        }
        let coeffs: &[(&'static str, f64)] = match self.distortion {
            Distortion::None => &[],
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                &[("k1", k1), ("k2", k2), ("p1", p1), ("p2", p2), ("k3", k3)]
            }
            Distortion::Fisheye { k1, k2, k3, k4 } => {
                &[("k1", k1), ("k2", k2), ("k3", k3), ("k4", k4)]
            }
        };
        for &(name, c) in coeffs {
            if !c.is_finite() {
                return Err(CameraError::invalid(
                    name,
                    c,
                    "a finite distortion coefficient",
                ));
            }
        }
        Ok(())
    }

    /// True when the model has no distortion.
    pub fn is_pinhole(&self) -> bool {
        matches!(self.distortion, Distortion::None)
    }

    /// The intrinsic matrix `[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`.
    pub fn k_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(
            self.fx, self.skew, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0,
        )
    }

    /// Projects a ray (any positive scale) to a pixel. `None` when the ray is outside the
    /// model's valid domain (see module docs); image bounds are *not* checked.
    /// Allocation-free; cheap enough for dense per-pixel grids.
    #[inline]
    pub fn project(&self, ray: &Vector3<f64>) -> Option<Vector2<f64>> {
        let (xd, yd) = distort(&self.distortion, ray.x, ray.y, ray.z)?;
        let u = self.fx * xd + self.skew * yd + self.cx;
        let v = self.fy * yd + self.cy;
        (u.is_finite() && v.is_finite()).then(|| Vector2::new(u, v))
    }

    /// Single-precision convenience wrapper around [`CameraModel::project`]
    /// (computes in f64 for accuracy).
    #[inline]
    pub fn project_f32(&self, ray: &Vector3<f32>) -> Option<Vector2<f32>> {
        self.project(&ray.cast::<f64>()).map(|p| p.cast::<f32>())
    }

    /// Back-projects a pixel to a unit-norm ray. `None` when the pixel lies outside the
    /// invertible domain of the distortion or the iteration fails to converge.
    pub fn unproject(&self, px: &Vector2<f64>) -> Option<Vector3<f64>> {
        let yd = (px.y - self.cy) / self.fy;
        let xd = (px.x - self.cx - self.skew * yd) / self.fx;
        if !(xd.is_finite() && yd.is_finite()) {
            return None;
        }
        let ray = match self.distortion {
            Distortion::None => Vector3::new(xd, yd, 1.0),
            Distortion::RadTan { k1, k2, p1, p2, k3 } => {
                let (x, y) = undistort_radtan(&RadTan { k1, k2, p1, p2, k3 }, xd, yd)?;
                Vector3::new(x, y, 1.0)
            }
            Distortion::Fisheye { k1, k2, k3, k4 } => {
                let theta_d = (xd * xd + yd * yd).sqrt();
                if theta_d == 0.0 {
                    return Some(Vector3::new(0.0, 0.0, 1.0));
                }
                let theta = undistort_fisheye(&[k1, k2, k3, k4], theta_d)?;
                let s = theta.sin() / theta_d;
                Vector3::new(xd * s, yd * s, theta.cos())
            }
        };
        let n = ray.norm();
        (n.is_finite() && n > 0.0).then(|| ray / n)
    }

    /// Single-precision convenience wrapper around [`CameraModel::unproject`].
    #[inline]
    pub fn unproject_f32(&self, px: &Vector2<f32>) -> Option<Vector3<f32>> {
        self.unproject(&px.cast::<f64>()).map(|r| r.cast::<f32>())
    }

    /// The same lens at another resolution, pixel-centre correct:
    /// `f' = f * s`, `c' = (c + 0.5) * s - 0.5` (per axis; skew scales with x).
    pub fn rescaled(&self, width: usize, height: usize) -> Self {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        Self {
            width,
            height,
            fx: self.fx * sx,
            fy: self.fy * sy,
            cx: (self.cx + 0.5) * sx - 0.5,
            cy: (self.cy + 0.5) * sy - 0.5,
            skew: self.skew * sx,
            distortion: self.distortion.clone(),
        }
    }

    /// Horizontal field of view (degrees) of the real lens across the full width, along
    /// the principal-point row: the angle from the ray of the left edge `(-0.5, cy)` to the
    /// ray of the right edge `(width - 0.5, cy)`, measured in the camera's x-z plane
    /// (so fisheye fields of view above 180 degrees are reported correctly).
    /// `NaN` when an edge lies outside the invertible domain; see [`Self::try_hfov_deg`].
    pub fn hfov_deg(&self) -> f64 {
        self.try_hfov_deg().unwrap_or(f64::NAN)
    }

    /// Like [`Self::hfov_deg`], but `None` when an edge pixel cannot be unprojected.
    pub fn try_hfov_deg(&self) -> Option<f64> {
        let l = self.unproject(&Vector2::new(-0.5, self.cy))?;
        let r = self.unproject(&Vector2::new(self.width as f64 - 0.5, self.cy))?;
        Some((r.x.atan2(r.z) - l.x.atan2(l.z)).to_degrees())
    }

    /// Supremum (radians) of the angle between a projectable ray and the optical axis:
    /// `pi/2` for pinhole, `atan(r_max)` for radtan, `theta_max` for fisheye.
    pub fn max_ray_angle(&self) -> f64 {
        match self.distortion {
            Distortion::None => PI / 2.0,
            Distortion::RadTan { k1, k2, k3, .. } => radtan_r2_limit(k1, k2, k3).sqrt().atan(),
            Distortion::Fisheye { k1, k2, k3, k4 } => fisheye_theta_limit(&[k1, k2, k3, k4]),
        }
    }
}

fn check_size(width: usize, height: usize) -> Result<(), CameraError> {
    if width == 0 {
        return Err(CameraError::invalid("width", width, ">= 1 pixel"));
    }
    if height == 0 {
        return Err(CameraError::invalid("height", height, ">= 1 pixel"));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Forward maps
// ---------------------------------------------------------------------------------------

/// Radial-tangential coefficients, unpacked.
struct RadTan {
    k1: f64,
    k2: f64,
    p1: f64,
    p2: f64,
    k3: f64,
}

/// Ray -> distorted normalized coordinates, or `None` outside the valid domain.
#[inline]
fn distort(d: &Distortion, x: f64, y: f64, z: f64) -> Option<(f64, f64)> {
    match *d {
        Distortion::None => perspective(x, y, z),
        Distortion::RadTan { k1, k2, p1, p2, k3 } => {
            let (a, b) = perspective(x, y, z)?;
            let s = a * a + b * b;
            if !monotone_on(&deriv_coeffs_radtan(k1, k2, k3), s) {
                return None;
            }
            Some(radtan_apply(&RadTan { k1, k2, p1, p2, k3 }, a, b))
        }
        Distortion::Fisheye { k1, k2, k3, k4 } => {
            let k = [k1, k2, k3, k4];
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
            if !(theta < PI) || !monotone_on(&deriv_coeffs_fisheye(&k), t) {
                return None;
            }
            let scale = theta * poly_eval(&odd_coeffs_fisheye(&k), t) / rxy;
            Some((x * scale, y * scale))
        }
    }
}

/// Perspective division with the `Z > eps * |ray|` domain check.
#[inline]
fn perspective(x: f64, y: f64, z: f64) -> Option<(f64, f64)> {
    let n2 = x * x + y * y + z * z;
    if !(z > 0.0 && n2.is_finite() && z * z > Z_EPS * Z_EPS * n2) {
        return None;
    }
    Some((x / z, y / z))
}

/// Applies radial-tangential distortion to undistorted normalized `(x, y)`.
#[inline]
fn radtan_apply(c: &RadTan, x: f64, y: f64) -> (f64, f64) {
    let s = x * x + y * y;
    let radial = 1.0 + s * (c.k1 + s * (c.k2 + s * c.k3));
    let xy = x * y;
    (
        x * radial + 2.0 * c.p1 * xy + c.p2 * (s + 2.0 * x * x),
        y * radial + c.p1 * (s + 2.0 * y * y) + 2.0 * c.p2 * xy,
    )
}

/// Radial-tangential distortion and its Jacobian `[[dX/dx, dX/dy], [dY/dx, dY/dy]]`.
#[inline]
fn radtan_with_jacobian(c: &RadTan, x: f64, y: f64) -> ((f64, f64), [[f64; 2]; 2]) {
    let s = x * x + y * y;
    let radial = 1.0 + s * (c.k1 + s * (c.k2 + s * c.k3));
    let dradial = c.k1 + s * (2.0 * c.k2 + s * 3.0 * c.k3); // d radial / d s
    let xy = x * y;
    let f = (
        x * radial + 2.0 * c.p1 * xy + c.p2 * (s + 2.0 * x * x),
        y * radial + c.p1 * (s + 2.0 * y * y) + 2.0 * c.p2 * xy,
    );
    let cross = 2.0 * xy * dradial + 2.0 * c.p1 * x + 2.0 * c.p2 * y;
    let j = [
        [
            radial + 2.0 * x * x * dradial + 2.0 * c.p1 * y + 6.0 * c.p2 * x,
            cross,
        ],
        [
            cross,
            radial + 2.0 * y * y * dradial + 6.0 * c.p1 * y + 2.0 * c.p2 * x,
        ],
    ];
    (f, j)
}

// ---------------------------------------------------------------------------------------
// Inverse maps
// ---------------------------------------------------------------------------------------

/// Inverts radial-tangential distortion: distorted `(xd, yd)` -> undistorted `(x, y)`.
fn undistort_radtan(c: &RadTan, xd: f64, yd: f64) -> Option<(f64, f64)> {
    let dcoef = deriv_coeffs_radtan(c.k1, c.k2, c.k3);
    // Fast path: Newton from the distorted point itself (converges for realistic lenses).
    if let Some((x, y)) = newton_radtan(c, xd, yd, xd, yd) {
        if monotone_on(&dcoef, x * x + y * y) {
            return Some((x, y));
        }
    }
    // Robust path: solve the radial part exactly inside the monotone range for a start.
    let rd = (xd * xd + yd * yd).sqrt();
    let s_lim = radtan_r2_limit(c.k1, c.k2, c.k3);
    let pcoef = [1.0, c.k1, c.k2, c.k3, 0.0];
    let r0 = invert_odd_poly(&pcoef, &dcoef, rd, s_lim.sqrt())?;
    let (x0, y0) = if rd > 0.0 {
        (xd * r0 / rd, yd * r0 / rd)
    } else {
        (0.0, 0.0)
    };
    let (x, y) = newton_radtan(c, xd, yd, x0, y0)?;
    (x * x + y * y < s_lim).then_some((x, y))
}

/// Damped 2-D Newton iteration for `distort(x, y) = (xd, yd)` from `(x0, y0)`.
fn newton_radtan(c: &RadTan, xd: f64, yd: f64, x0: f64, y0: f64) -> Option<(f64, f64)> {
    let scale = 1.0 + xd.abs().max(yd.abs());
    let (mut x, mut y) = (x0, y0);
    let residual = |x: f64, y: f64| {
        let (fx, fy) = radtan_apply(c, x, y);
        (fx - xd).abs().max((fy - yd).abs())
    };
    let mut err = residual(x, y);
    for _ in 0..MAX_NEWTON {
        if !err.is_finite() {
            return None;
        }
        if err <= 1e-15 * scale {
            break;
        }
        let ((fx, fy), j) = radtan_with_jacobian(c, x, y);
        let (ex, ey) = (fx - xd, fy - yd);
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        if !(det.abs() > 1e-300) || !det.is_finite() {
            break;
        }
        let dx = (j[1][1] * ex - j[0][1] * ey) / det;
        let dy = (-j[1][0] * ex + j[0][0] * ey) / det;
        // Backtracking line search on the residual.
        let mut step = 1.0;
        let mut improved = false;
        for _ in 0..40 {
            let (nx, ny) = (x - step * dx, y - step * dy);
            let nerr = residual(nx, ny);
            if nerr < err {
                x = nx;
                y = ny;
                err = nerr;
                improved = true;
                break;
            }
            step *= 0.5;
        }
        if !improved {
            break;
        }
    }
    (err <= 1e-10 * scale && x.is_finite() && y.is_finite()).then_some((x, y))
}

/// Inverts the fisheye map `theta_d(theta)` for `theta` in `[0, theta_max)`.
fn undistort_fisheye(k: &[f64; 4], theta_d: f64) -> Option<f64> {
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

/// Solves `r * P(r^2) = target` for `r` in `[0, r_hi)`, where `D(r^2) = d/dr [r P(r^2)]` is
/// positive on `[0, r_hi)` (`r_hi` may be infinite). Safeguarded Newton (Newton steps that
/// leave the bracket become bisections). `None` if the target is not reached below `r_hi`.
fn invert_odd_poly(p: &[f64; 5], d: &[f64; 5], target: f64, r_hi: f64) -> Option<f64> {
    if !(target.is_finite() && target >= 0.0) || r_hi.is_nan() {
        return None;
    }
    let g = |r: f64| r * poly_eval(p, r * r) - target;
    if target == 0.0 {
        return Some(0.0);
    }
    // Bracket [lo, hi] with g(lo) < 0 <= g(hi).
    let hi = if r_hi.is_finite() {
        if !(g(r_hi) > 0.0) {
            return None;
        }
        r_hi
    } else {
        let mut hi = 1.0_f64.max(target);
        let mut n = 0;
        while !(g(hi) > 0.0) {
            hi *= 2.0;
            n += 1;
            if n > 200 || !hi.is_finite() {
                return None;
            }
        }
        hi
    };
    let (mut lo, mut hi) = (0.0_f64, hi);
    let mut r = target.min(0.5 * (lo + hi)).max(0.0);
    for _ in 0..200 {
        let gr = g(r);
        if !gr.is_finite() {
            return None;
        }
        if gr == 0.0 {
            return Some(r);
        }
        if gr < 0.0 {
            lo = r;
        } else {
            hi = r;
        }
        let dg = poly_eval(d, r * r);
        let newton = r - gr / dg;
        let next = if dg > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - r).abs() <= 1e-15 * (1.0 + r) || hi - lo <= 1e-15 * (1.0 + hi) {
            return (next < r_hi).then_some(next);
        }
        r = next;
    }
    (r < r_hi).then_some(r)
}

// ---------------------------------------------------------------------------------------
// Validity limits: polynomials in s = r^2 (radtan) or t = theta^2 (fisheye)
// ---------------------------------------------------------------------------------------

/// `1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3`: derivative of the radial map `r (1 + k1 r^2 + ...)`.
#[inline]
fn deriv_coeffs_radtan(k1: f64, k2: f64, k3: f64) -> [f64; 5] {
    [1.0, 3.0 * k1, 5.0 * k2, 7.0 * k3, 0.0]
}

/// `1 + k1 t + k2 t^2 + k3 t^3 + k4 t^4`, so `theta_d = theta * P(theta^2)`.
#[inline]
fn odd_coeffs_fisheye(k: &[f64; 4]) -> [f64; 5] {
    [1.0, k[0], k[1], k[2], k[3]]
}

/// `1 + 3 k1 t + 5 k2 t^2 + 7 k3 t^3 + 9 k4 t^4 = d theta_d / d theta`.
#[inline]
fn deriv_coeffs_fisheye(k: &[f64; 4]) -> [f64; 5] {
    [1.0, 3.0 * k[0], 5.0 * k[1], 7.0 * k[2], 9.0 * k[3]]
}

/// Horner evaluation of `c[0] + c[1] t + ... + c[4] t^4`.
#[inline]
fn poly_eval(c: &[f64; 5], t: f64) -> f64 {
    (((c[4] * t + c[3]) * t + c[2]) * t + c[1]) * t + c[0]
}

/// True when the derivative polynomial `c` (with `c[0] = 1`) is positive on `[0, t]`,
/// i.e. the distortion map is strictly increasing up to `t`. Cheap sufficient bound first
/// (drop the positive terms), exact critical-point test only when that is inconclusive.
#[inline]
fn monotone_on(c: &[f64; 5], t: f64) -> bool {
    if !(t >= 0.0 && t.is_finite()) {
        return false;
    }
    let neg = |v: f64| v.min(0.0);
    let bound = 1.0 + t * (neg(c[1]) + t * (neg(c[2]) + t * (neg(c[3]) + t * neg(c[4]))));
    if bound > 0.0 {
        return true;
    }
    monotone_on_exact(c, t)
}

/// Exact version of [`monotone_on`]: the minimum of a polynomial on an interval is at an
/// end point or at a root of its derivative.
#[cold]
fn monotone_on_exact(c: &[f64; 5], t: f64) -> bool {
    if !(poly_eval(c, 0.0) > 0.0 && poly_eval(c, t) > 0.0) {
        return false;
    }
    let mut crit = [0.0; 4];
    let n = if c[4] == 0.0 {
        // Cubic (radtan): critical points in closed form, no iteration.
        quadratic_roots(c[1], 2.0 * c[2], 3.0 * c[3], &mut crit)
    } else {
        roots_in(&derivative(c), 0.0, t, &mut crit)
    };
    crit[..n]
        .iter()
        .all(|&s| !(s > 0.0 && s < t) || poly_eval(c, s) > 0.0)
}

/// Real roots of `a + b s + c s^2` (any order, at most 2) written to `out`.
#[inline]
fn quadratic_roots(a: f64, b: f64, c: f64, out: &mut [f64; 4]) -> usize {
    if c == 0.0 {
        if b == 0.0 {
            return 0;
        }
        out[0] = -a / b;
        return 1;
    }
    let disc = b * b - 4.0 * a * c;
    if !(disc >= 0.0) {
        return 0;
    }
    // Numerically stable form: q = -(b + sign(b) sqrt(disc)) / 2, roots q/c and a/q.
    let q = -0.5 * (b + disc.sqrt().copysign(b));
    out[0] = q / c;
    if q == 0.0 {
        return 1;
    }
    out[1] = a / q;
    2
}

/// Smallest `s = r^2` at which the radtan radial map stops increasing (`+inf` if never).
fn radtan_r2_limit(k1: f64, k2: f64, k3: f64) -> f64 {
    first_positive_root(&deriv_coeffs_radtan(k1, k2, k3), f64::INFINITY).unwrap_or(f64::INFINITY)
}

/// `theta_max = min(pi, first theta at which theta_d(theta) stops increasing)`.
fn fisheye_theta_limit(k: &[f64; 4]) -> f64 {
    match first_positive_root(&deriv_coeffs_fisheye(k), PI * PI) {
        Some(t) => t.sqrt().min(PI),
        None => PI,
    }
}

/// Smallest root of `c` (with `c[0] > 0`) in `(0, hi]`; `hi` may be infinite, in which
/// case the Cauchy bound on the root magnitudes is used.
fn first_positive_root(c: &[f64; 5], hi: f64) -> Option<f64> {
    if c.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let hi = if hi.is_finite() {
        hi
    } else {
        let n = degree(c);
        if n == 0 {
            return None;
        }
        1.0 + c[..n].iter().map(|v| (v / c[n]).abs()).fold(0.0, f64::max)
    };
    let mut roots = [0.0; 4];
    let n = roots_in(c, 0.0, hi, &mut roots);
    roots[..n].iter().copied().find(|&r| r > 0.0)
}

/// Degree of the polynomial (index of the last non-zero coefficient).
#[inline]
fn degree(c: &[f64; 5]) -> usize {
    let mut d = 4;
    while d > 0 && c[d] == 0.0 {
        d -= 1;
    }
    d
}

/// Coefficients of the derivative.
#[inline]
fn derivative(c: &[f64; 5]) -> [f64; 5] {
    [c[1], 2.0 * c[2], 3.0 * c[3], 4.0 * c[4], 0.0]
}

/// All real roots of `c` in `[lo, hi]`, ascending (at most 4), written to `out`.
/// Splits the interval at the roots of the derivative (found recursively) into monotone
/// pieces and bisects each piece that changes sign. Roots of even multiplicity that do not
/// change sign are found only when they coincide with a critical point (which they do).
fn roots_in(c: &[f64; 5], lo: f64, hi: f64, out: &mut [f64; 4]) -> usize {
    if !(lo <= hi) {
        return 0;
    }
    let deg = degree(c);
    if deg == 0 {
        return 0;
    }
    if deg == 1 {
        let r = -c[0] / c[1];
        if r >= lo && r <= hi {
            out[0] = r;
            return 1;
        }
        return 0;
    }
    let mut crit = [0.0; 4];
    let nc = roots_in(&derivative(c), lo, hi, &mut crit);
    let mut n = 0;
    let mut push = |r: f64, n: &mut usize| {
        if *n < 4 && (*n == 0 || out[*n - 1] < r) {
            out[*n] = r;
            *n += 1;
        }
    };
    let mut a = lo;
    let mut fa = poly_eval(c, lo);
    if fa == 0.0 {
        push(lo, &mut n);
    }
    for b in crit[..nc].iter().copied().chain(std::iter::once(hi)) {
        if b <= a {
            continue;
        }
        let fb = poly_eval(c, b);
        if fb == 0.0 {
            push(b, &mut n);
        } else if fa != 0.0 && (fa < 0.0) != (fb < 0.0) {
            push(bisect(c, a, b, fa), &mut n);
        }
        a = b;
        fa = fb;
    }
    n
}

/// Bisection for a sign change of `c` on `[a, b]` (`fa = c(a)`), to full precision.
fn bisect(c: &[f64; 5], mut a: f64, mut b: f64, fa: f64) -> f64 {
    let neg_a = fa < 0.0;
    for _ in 0..2100 {
        let m = 0.5 * (a + b);
        if !(m > a && m < b) {
            break;
        }
        let fm = poly_eval(c, m);
        if fm == 0.0 {
            return m;
        }
        if (fm < 0.0) == neg_a {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    fn radtan_cam() -> CameraModel {
        CameraModel {
            width: 1280,
            height: 960,
            fx: 700.0,
            fy: 702.5,
            cx: 645.3,
            cy: 478.9,
            skew: 0.8,
            distortion: Distortion::RadTan {
                k1: -0.28,
                k2: 0.07,
                p1: 1e-4,
                p2: -2e-4,
                k3: 0.0,
            },
        }
    }

    const FK: [f64; 4] = [0.05, -0.01, 0.002, -0.0005];

    fn fisheye_cam(hfov: f64) -> CameraModel {
        let mut c = CameraModel::fisheye_hfov(1280, 960, hfov, FK).expect("valid fisheye");
        c.cx += 3.7;
        c.cy -= 2.1;
        c.fy *= 1.002;
        c.skew = -0.4;
        c
    }

    fn pinhole_cam() -> CameraModel {
        CameraModel {
            skew: -0.6974,
            ..CameraModel::pinhole(800, 600, 573.8534, 575.0448, 406.0101, 309.0112)
        }
    }

    fn assert_pixel_round_trip(cam: &CameraModel, u: f64, v: f64) {
        let px = Vector2::new(u, v);
        let ray = cam
            .unproject(&px)
            .unwrap_or_else(|| panic!("unproject failed at {px:?}"));
        assert_relative_eq!(ray.norm(), 1.0, epsilon = 1e-12);
        let back = cam
            .project(&ray)
            .unwrap_or_else(|| panic!("project failed for {ray:?}"));
        assert!((back - px).norm() < 1e-7, "{px:?} -> {ray:?} -> {back:?}");
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]

        #[test]
        fn pinhole_pixel_round_trip(u in -0.5f64..799.5, v in -0.5f64..599.5) {
            assert_pixel_round_trip(&pinhole_cam(), u, v);
        }

        #[test]
        fn radtan_pixel_round_trip(u in -0.5f64..1279.5, v in -0.5f64..959.5) {
            assert_pixel_round_trip(&radtan_cam(), u, v);
        }

        #[test]
        fn fisheye_pixel_round_trip(u in -0.5f64..1279.5, v in -0.5f64..959.5) {
            assert_pixel_round_trip(&fisheye_cam(160.0), u, v);
        }

        #[test]
        fn ray_round_trip(
            az in -PI..PI,
            el_frac in 0.0f64..0.999,
            scale in 1e-3f64..1e3,
            which in 0usize..4,
        ) {
            let (cam, max_angle) = match which {
                0 => (pinhole_cam(), 1.4),
                1 => (radtan_cam(), 1.2),
                2 => (fisheye_cam(160.0), fisheye_cam(160.0).max_ray_angle()),
                _ => (fisheye_cam(220.0), fisheye_cam(220.0).max_ray_angle()),
            };
            let theta = el_frac * max_angle;
            let ray = Vector3::new(theta.sin() * az.cos(), theta.sin() * az.sin(), theta.cos());
            let px = cam.project(&(ray * scale)).expect("ray inside the valid domain");
            let back = cam.unproject(&px).expect("pixel inside the invertible domain");
            prop_assert!((back - ray).norm() < 1e-9, "{:?} -> {:?} -> {:?}", ray, px, back);
        }

        #[test]
        fn rescale_law(
            x in -0.8f64..0.8, y in -0.6f64..0.6,
            w in 100usize..4000, h in 100usize..3000, which in 0usize..3,
        ) {
            let cam = match which { 0 => pinhole_cam(), 1 => radtan_cam(), _ => fisheye_cam(160.0) };
            let (sx, sy) = (w as f64 / cam.width as f64, h as f64 / cam.height as f64);
            let ray = Vector3::new(x, y, 1.0);
            let p = cam.project(&ray).expect("valid ray");
            let q = cam.rescaled(w, h).project(&ray).expect("valid ray");
            prop_assert!((q.x - ((p.x + 0.5) * sx - 0.5)).abs() < 1e-8);
            prop_assert!((q.y - ((p.y + 0.5) * sy - 0.5)).abs() < 1e-8);
        }

        #[test]
        fn monotone_check_matches_sampling(
            k in prop::array::uniform4(-1.0f64..1.0),
            cubic in any::<bool>(),
            t in 0.0f64..10.0,
        ) {
            let c = if cubic {
                deriv_coeffs_radtan(k[0], k[1], k[2])
            } else {
                deriv_coeffs_fisheye(&k)
            };
            let min = (0..=4000).map(|i| poly_eval(&c, t * i as f64 / 4000.0)).fold(f64::INFINITY, f64::min);
            let got = monotone_on(&c, t);
            if min > 1e-9 {
                prop_assert!(got, "{:?} t={} min={}", c, t, min);
            } else if min < -1e-9 {
                prop_assert!(!got, "{:?} t={} min={}", c, t, min);
            }
            // The limit functions agree with the check.
            let lim = first_positive_root(&c, f64::INFINITY).unwrap_or(f64::INFINITY);
            if t < lim * (1.0 - 1e-9) {
                prop_assert!(monotone_on(&c, t));
            } else if t > lim * (1.0 + 1e-9) {
                prop_assert!(!monotone_on(&c, t));
            }
        }
    }

    #[test]
    fn radtan_matches_hand_computation() {
        let cam = CameraModel {
            width: 1000,
            height: 800,
            fx: 500.0,
            fy: 510.0,
            cx: 499.5,
            cy: 399.5,
            skew: 0.0,
            distortion: Distortion::RadTan {
                k1: -0.28,
                k2: 0.07,
                p1: 1e-4,
                p2: -2e-4,
                k3: 0.01,
            },
        };
        // Ray (0.6, -0.4, 2): x = 0.3, y = -0.2, r^2 = 0.13,
        // radial = 1 - 0.28*0.13 + 0.07*0.0169 + 0.01*0.002197 = 0.96480497
        // xd = 0.3*radial + 2*p1*x*y + p2*(r^2 + 2x^2) = 0.28944149 - 0.000012 - 0.000062 = 0.289367491
        // yd = -0.2*radial + p1*(r^2 + 2y^2) + 2*p2*x*y = -0.19296099 + 0.000021 + 0.000024 = -0.192915994
        // u = 500*xd + 499.5 = 644.1837455, v = 510*yd + 399.5 = 301.112843
        let p = cam.project(&Vector3::new(0.6, -0.4, 2.0)).expect("valid");
        assert_relative_eq!(p.x, 644.1837455, epsilon = 1e-6);
        assert_relative_eq!(p.y, 301.1128431, epsilon = 1e-6);
    }

    #[test]
    fn fisheye_matches_hand_computation() {
        let cam = CameraModel {
            width: 1000,
            height: 800,
            fx: 400.0,
            fy: 401.0,
            cx: 500.0,
            cy: 400.0,
            skew: 2.0,
            distortion: Distortion::Fisheye {
                k1: FK[0],
                k2: FK[1],
                k3: FK[2],
                k4: FK[3],
            },
        };
        // Ray (3, 4, 5): sqrt(X^2+Y^2) = 5, theta = pi/4, t = theta^2 = 0.6168503,
        // theta_d = theta (1 + 0.05 t - 0.01 t^2 + 0.002 t^3 - 0.0005 t^4) = 0.80694518
        // xd = 0.6 theta_d, yd = 0.8 theta_d
        // u = 400 xd + 2 yd + 500 = 694.957954, v = 401 yd + 400 = 658.868012
        let p = cam.project(&Vector3::new(3.0, 4.0, 5.0)).expect("valid");
        assert_relative_eq!(p.x, 694.9579544, epsilon = 1e-6);
        assert_relative_eq!(p.y, 658.8680123, epsilon = 1e-6);
        // A ray behind the image plane (theta = atan2(1, -0.4) = 111.8 deg) is valid here.
        let th = 1.0f64.atan2(-0.4);
        let t = th * th;
        let td = th * (1.0 + 0.05 * t - 0.01 * t * t + 0.002 * t * t * t - 0.0005 * t * t * t * t);
        let back = cam
            .project(&Vector3::new(1.0, 0.0, -0.4))
            .expect("theta < limit");
        assert_relative_eq!(back.x, 400.0 * td + 500.0, epsilon = 1e-9);
        assert_relative_eq!(back.y, 400.0, epsilon = 1e-12);
        // 135 degrees is beyond this polynomial's monotone range.
        assert!(cam.project(&Vector3::new(1.0, 0.0, -1.0)).is_none());
    }

    #[test]
    fn validity_limits() {
        // k1 = -0.28 only: d/dr r(1 + k1 r^2) = 1 - 0.84 r^2 = 0 at r^2 = 1/0.84.
        let cam = CameraModel {
            distortion: Distortion::RadTan {
                k1: -0.28,
                k2: 0.0,
                p1: 0.0,
                p2: 0.0,
                k3: 0.0,
            },
            ..pinhole_cam()
        };
        let r_max = (1.0f64 / 0.84).sqrt();
        assert_relative_eq!(cam.max_ray_angle(), r_max.atan(), epsilon = 1e-12);
        assert!(cam
            .project(&Vector3::new(r_max * 0.999, 0.0, 1.0))
            .is_some());
        assert!(cam
            .project(&Vector3::new(r_max * 1.001, 0.0, 1.0))
            .is_none());
        // Pixel beyond the maximum distorted radius is not invertible.
        let rd_max = r_max * (1.0 - 0.28 * r_max * r_max);
        let inside = Vector2::new(cam.cx + cam.fx * rd_max * 0.99, cam.cy);
        let outside = Vector2::new(cam.cx + cam.fx * rd_max * 1.01, cam.cy);
        assert!(cam.unproject(&inside).is_some());
        assert!(cam.unproject(&outside).is_none());
        // Realistic radtan: monotone everywhere (1 - 0.84 s + 0.35 s^2 > 0).
        assert_eq!(radtan_cam().max_ray_angle(), PI / 2.0);
        // Pinhole / radtan reject rays at or behind 90 degrees.
        for cam in [pinhole_cam(), radtan_cam()] {
            assert!(cam.project(&Vector3::new(1.0, 0.0, 0.0)).is_none());
            assert!(cam.project(&Vector3::new(0.0, 1.0, -0.5)).is_none());
            assert!(cam.project(&Vector3::zeros()).is_none());
            assert!(cam.project(&Vector3::new(f64::NAN, 0.0, 1.0)).is_none());
        }
        // Fisheye: limit is the first root of 1 + 0.15 t - 0.05 t^2 + 0.014 t^3 - 0.0045 t^4.
        let f = fisheye_cam(160.0);
        let lim = f.max_ray_angle();
        let d = |th: f64| {
            let t = th * th;
            1.0 + 0.15 * t - 0.05 * t * t + 0.014 * t * t * t - 0.0045 * t * t * t * t
        };
        assert!(d(lim).abs() < 1e-9, "derivative at limit {}", d(lim));
        assert!(lim > 2.0 && lim < PI);
        let ray = |th: f64| Vector3::new(th.sin(), 0.0, th.cos());
        assert!(f.project(&ray(lim - 1e-6)).is_some());
        assert!(f.project(&ray(lim + 1e-6)).is_none());
        assert!(f.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
        assert!(f.project(&Vector3::new(0.0, 0.0, 1.0)).is_some());
        // Equidistant fisheye (all k zero) is valid up to (not including) pi.
        let eq = CameraModel::fisheye_hfov(1000, 1000, 350.0, [0.0; 4]).expect("valid");
        assert_eq!(eq.max_ray_angle(), PI);
        assert_relative_eq!(eq.hfov_deg(), 350.0, epsilon = 1e-9);
    }

    #[test]
    fn strong_distortion_inverts() {
        // Strong barrel with a k3 term: fixed-point iteration would diverge near the edge.
        let cam = CameraModel {
            distortion: Distortion::RadTan {
                k1: -0.45,
                k2: 0.25,
                p1: 1e-3,
                p2: -1e-3,
                k3: -0.06,
            },
            ..radtan_cam()
        };
        let lim = cam.max_ray_angle();
        for i in 0..200 {
            let th = lim * (i as f64 + 0.5) / 200.0 * 0.999;
            for az in [0.0, 0.7, 2.0, -2.5] {
                let ray = Vector3::new(th.sin() * f64::cos(az), th.sin() * f64::sin(az), th.cos());
                let px = cam.project(&ray).expect("valid");
                let back = cam.unproject(&px).expect("invertible");
                assert!(
                    (back - ray).norm() < 1e-8,
                    "theta {th}: {ray:?} -> {back:?}"
                );
            }
        }
    }

    #[test]
    fn hfov_of_constructors() {
        for hfov in [1.0, 30.0, 90.0, 120.0, 179.0] {
            let cam = CameraModel::pinhole_hfov(1920, 1080, hfov).expect("valid");
            assert_relative_eq!(cam.hfov_deg(), hfov, epsilon = 1e-9);
            assert_relative_eq!(cam.cx, 959.5);
            assert_relative_eq!(cam.cy, 539.5);
        }
        for hfov in [60.0, 150.0, 190.0, 220.0] {
            let cam = CameraModel::fisheye_hfov(1280, 960, hfov, FK).expect("valid");
            assert_relative_eq!(cam.hfov_deg(), hfov, epsilon = 1e-9);
        }
        // Distorted lens: barrel distortion widens the field of view versus the pinhole.
        let r = radtan_cam();
        let pin = CameraModel {
            distortion: Distortion::None,
            ..r.clone()
        };
        assert!(r.hfov_deg() > pin.hfov_deg() + 5.0);
    }

    #[test]
    fn invalid_values_rejected() {
        use CameraError::Invalid;
        let name = |r: Result<CameraModel, CameraError>| match r {
            Err(Invalid { name, .. }) => name,
            Ok(_) => "ok",
        };
        assert_eq!(name(CameraModel::pinhole_hfov(640, 480, 0.0)), "hfov_deg");
        assert_eq!(name(CameraModel::pinhole_hfov(640, 480, 179.5)), "hfov_deg");
        assert_eq!(
            name(CameraModel::pinhole_hfov(640, 480, f64::NAN)),
            "hfov_deg"
        );
        assert_eq!(name(CameraModel::pinhole_hfov(640, 480, 179.0)), "ok");
        assert_eq!(name(CameraModel::pinhole_hfov(0, 480, 90.0)), "width");
        assert_eq!(name(CameraModel::pinhole_hfov(640, 0, 90.0)), "height");
        assert_eq!(
            name(CameraModel::fisheye_hfov(640, 480, 360.0, FK)),
            "hfov_deg"
        );
        assert_eq!(
            name(CameraModel::fisheye_hfov(640, 480, 300.0, FK)),
            "hfov_deg"
        );
        assert_eq!(
            name(CameraModel::fisheye_hfov(
                640,
                480,
                120.0,
                [f64::NAN, 0.0, 0.0, 0.0]
            )),
            "fisheye coefficients"
        );

        let check = |c: CameraModel| match c.validate() {
            Err(Invalid { name, .. }) => name,
            Ok(()) => "ok",
        };
        let good = radtan_cam();
        assert_eq!(check(good.clone()), "ok");
        assert_eq!(
            check(CameraModel {
                fx: -500.0,
                ..good.clone()
            }),
            "fx"
        );
        assert_eq!(
            check(CameraModel {
                fx: f64::INFINITY,
                ..good.clone()
            }),
            "fx"
        );
        assert_eq!(
            check(CameraModel {
                fy: 0.0,
                ..good.clone()
            }),
            "fy"
        );
        assert_eq!(
            check(CameraModel {
                cx: f64::NAN,
                ..good.clone()
            }),
            "cx"
        );
        assert_eq!(
            check(CameraModel {
                cx: 5000.0,
                ..good.clone()
            }),
            "cx"
        );
        assert_eq!(
            check(CameraModel {
                cy: -2000.0,
                ..good.clone()
            }),
            "cy"
        );
        assert_eq!(
            check(CameraModel {
                skew: f64::NAN,
                ..good.clone()
            }),
            "skew"
        );
        assert_eq!(
            check(CameraModel {
                width: 0,
                ..good.clone()
            }),
            "width"
        );
        assert_eq!(
            check(CameraModel {
                distortion: Distortion::RadTan {
                    k1: 0.0,
                    k2: 0.0,
                    p1: f64::NAN,
                    p2: 0.0,
                    k3: 0.0
                },
                ..good.clone()
            }),
            "p1"
        );
        assert_eq!(
            check(CameraModel {
                distortion: Distortion::Fisheye {
                    k1: 0.0,
                    k2: 0.0,
                    k3: 0.0,
                    k4: f64::INFINITY
                },
                ..good
            }),
            "k4"
        );
        let msg = CameraModel::pinhole_hfov(640, 480, 200.0)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("hfov_deg") && msg.contains("200") && msg.contains("(0, 179]"),
            "{msg}"
        );
    }

    #[test]
    fn invalid_models_do_not_panic() {
        let bad = CameraModel {
            fx: 0.0,
            fy: f64::NAN,
            distortion: Distortion::Fisheye {
                k1: f64::NAN,
                k2: 1e300,
                k3: -1e300,
                k4: 0.0,
            },
            ..pinhole_cam()
        };
        assert!(bad.project(&Vector3::new(0.1, 0.2, 1.0)).is_none());
        assert!(bad.unproject(&Vector2::new(10.0, 20.0)).is_none());
        let _ = bad.max_ray_angle();
        let _ = bad.hfov_deg();
        let weird = CameraModel {
            distortion: Distortion::RadTan {
                k1: 1e200,
                k2: -1e200,
                p1: 1e10,
                p2: -1e10,
                k3: 1e-300,
            },
            ..pinhole_cam()
        };
        let _ = weird.project(&Vector3::new(0.1, 0.2, 1.0));
        let _ = weird.unproject(&Vector2::new(10.0, 20.0));
        let _ = weird.max_ray_angle();
    }

    #[test]
    fn k_matrix_layout() {
        let k = pinhole_cam().k_matrix();
        assert_eq!(k[(0, 0)], 573.8534);
        assert_eq!(k[(0, 1)], -0.6974);
        assert_eq!(k[(0, 2)], 406.0101);
        assert_eq!(k[(1, 1)], 575.0448);
        assert_eq!(k[(1, 2)], 309.0112);
        assert_eq!(k[(2, 2)], 1.0);
        assert_eq!(k[(1, 0)], 0.0);
    }
}
