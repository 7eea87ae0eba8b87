//! The camera type, its parameter checks and the model-independent methods
//! (projection through the intrinsics, rescaling, field of view).

use super::fisheye::{self, fisheye_theta_limit, undistort_fisheye};
use super::pinhole::perspective;
use super::radtan::{self, radtan_r2_limit, undistort_radtan, RadTan};
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
    /// An [`CameraError::Invalid`] for `name` with `value` and the allowed range.
    pub(super) fn invalid(
        name: &'static str,
        value: impl std::fmt::Display,
        allowed: &'static str,
    ) -> Self {
        CameraError::Invalid {
            name,
            value: value.to_string(),
            allowed,
        }
    }
}

/// Lens distortion model (the equations are in `camera/pinhole.rs`, `radtan.rs` and `fisheye.rs`).
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
impl CameraModel {
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

pub(super) fn check_size(width: usize, height: usize) -> Result<(), CameraError> {
    if width == 0 {
        return Err(CameraError::invalid("width", width, ">= 1 pixel"));
    }
    if height == 0 {
        return Err(CameraError::invalid("height", height, ">= 1 pixel"));
    }
    Ok(())
}

/// Ray -> distorted normalized coordinates, or `None` outside the valid domain.
#[inline]
fn distort(d: &Distortion, x: f64, y: f64, z: f64) -> Option<(f64, f64)> {
    match *d {
        Distortion::None => perspective(x, y, z),
        Distortion::RadTan { k1, k2, p1, p2, k3 } => {
            radtan::distort(&RadTan { k1, k2, p1, p2, k3 }, x, y, z)
        }
        Distortion::Fisheye { k1, k2, k3, k4 } => fisheye::distort(&[k1, k2, k3, k4], x, y, z),
    }
}
