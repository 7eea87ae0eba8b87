//! Camera models: pinhole, OpenCV radial-tangential and OpenCV fisheye (Kannala-Brandt).
//! (Contract only: bodies are being implemented.)

use nalgebra::{Matrix3, Vector2, Vector3};
use serde::{Deserialize, Serialize};
use thiserror::Error;

#[derive(Debug, Error, Clone, PartialEq)]
pub enum CameraError {
    #[error("invalid camera {name}: {value} (allowed: {allowed})")]
    Invalid { name: &'static str, value: String, allowed: &'static str },
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "lowercase")]
pub enum Distortion {
    None,
    RadTan { k1: f64, k2: f64, p1: f64, p2: f64, k3: f64 },
    Fisheye { k1: f64, k2: f64, k3: f64, k4: f64 },
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CameraModel {
    pub width: usize,
    pub height: usize,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub skew: f64,
    pub distortion: Distortion,
}

impl CameraModel {
    pub fn pinhole(width: usize, height: usize, fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self { width, height, fx, fy, cx, cy, skew: 0.0, distortion: Distortion::None }
    }
    pub fn pinhole_hfov(width: usize, height: usize, hfov_deg: f64) -> Result<Self, CameraError> {
        let fx = (width as f64 / 2.0) / (hfov_deg.to_radians() / 2.0).tan();
        Ok(Self::pinhole(width, height, fx, fx, (width as f64 - 1.0) / 2.0, (height as f64 - 1.0) / 2.0))
    }
    pub fn validate(&self) -> Result<(), CameraError> { Ok(()) }
    pub fn is_pinhole(&self) -> bool { matches!(self.distortion, Distortion::None) }
    pub fn k_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, self.skew, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }
    pub fn project(&self, ray: &Vector3<f64>) -> Option<Vector2<f64>> {
        if ray.z <= 1e-9 { return None; }
        let (x, y) = (ray.x / ray.z, ray.y / ray.z);
        Some(Vector2::new(self.fx * x + self.skew * y + self.cx, self.fy * y + self.cy))
    }
    pub fn unproject(&self, px: &Vector2<f64>) -> Option<Vector3<f64>> {
        let y = (px.y - self.cy) / self.fy;
        let x = (px.x - self.cx - self.skew * y) / self.fx;
        Some(Vector3::new(x, y, 1.0).normalize())
    }
    pub fn rescaled(&self, width: usize, height: usize) -> Self {
        let sx = width as f64 / self.width as f64;
        let sy = height as f64 / self.height as f64;
        Self { width, height, fx: self.fx * sx, fy: self.fy * sy, cx: (self.cx + 0.5) * sx - 0.5,
               cy: (self.cy + 0.5) * sy - 0.5, skew: self.skew * sx, distortion: self.distortion.clone() }
    }
    pub fn hfov_deg(&self) -> f64 { 2.0 * ((self.width as f64 / 2.0) / self.fx).atan().to_degrees() }
}
