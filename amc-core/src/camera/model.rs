//! The camera types, their parameter checks and the model-independent methods
//! (intrinsic matrix, rescaling).
//!
//! The bottom layer of `camera/`: the per-model files (`pinhole.rs`, `radtan.rs`,
//! `fisheye.rs`) build on these types, and the methods that dispatch on the distortion
//! model live above them all, in `projection.rs`. Nothing here calls a model's equations.

use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};
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
    /// A camera of `width x height` pixels with the intrinsics `[fx, fy, cx,
    /// cy, skew]` and the lens `distortion`, unchecked (see
    /// [`CameraModel::validate`]): every lens file's camera is made here.
    pub(crate) fn from_intrinsics(
        width: usize,
        height: usize,
        [fx, fy, cx, cy, skew]: [f64; 5],
        distortion: Distortion,
    ) -> Self {
        Self {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            skew,
            distortion,
        }
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
