//! The methods that depend on the distortion model: projection, back-projection and the
//! field-of-view limits. Each `match`es on [`Distortion`] and calls the per-model file's
//! free functions.
//!
//! They live here, above `model.rs` (the types) and the per-model files, so that
//! dependencies point one way: the per-model files use the types and never call back into
//! the dispatch, and `model.rs` knows no model's equations.

use super::fisheye::{self, fisheye_theta_limit, undistort_fisheye};
use super::model::{CameraModel, Distortion};
use super::pinhole::perspective;
use super::radtan::{self, radtan_r2_limit, undistort_radtan, RadTan};
use nalgebra::{Vector2, Vector3};
use std::f64::consts::PI;

impl CameraModel {
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
