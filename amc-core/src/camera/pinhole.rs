//! Pinhole camera (`Distortion::None`), valid for `Z > eps * |ray|`:
//! ```text
//! xd = X / Z,  yd = Y / Z
//! ```

use super::model::{check_size, CameraError, CameraModel, Distortion};

/// Relative bound on `Z / |ray|` below which pinhole and radtan rays are rejected.
pub(super) const Z_EPS: f64 = 1e-9;

impl CameraModel {
    /// An undistorted pinhole camera.
    pub fn pinhole(width: usize, height: usize, fx: f64, fy: f64, cx: f64, cy: f64) -> Self {
        Self::from_intrinsics(width, height, [fx, fy, cx, cy, 0.0], Distortion::None)
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
}

/// Perspective division with the `Z > eps * |ray|` domain check.
#[inline]
pub(super) fn perspective(x: f64, y: f64, z: f64) -> Option<(f64, f64)> {
    let n2 = x * x + y * y + z * z;
    if !(z > 0.0 && n2.is_finite() && z * z > Z_EPS * Z_EPS * n2) {
        return None;
    }
    Some((x / z, y / z))
}
