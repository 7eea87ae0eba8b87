//! Pinhole intrinsics of one pyramid level, in `f32` for the hot loops.

use crate::camera::CameraModel;

/// Pinhole intrinsics at one pyramid level, in `f32` for the hot loop.
#[derive(Clone, Copy, Debug)]
pub(super) struct Intrinsics {
    pub(super) fx: f32,
    pub(super) fy: f32,
    pub(super) skew: f32,
    pub(super) cx: f32,
    pub(super) cy: f32,
}

impl Intrinsics {
    pub(super) fn from_camera(cam: &CameraModel) -> Self {
        Self {
            fx: cam.fx as f32,
            fy: cam.fy as f32,
            skew: cam.skew as f32,
            cx: cam.cx as f32,
            cy: cam.cy as f32,
        }
    }
    /// The same camera after a 2x2 box halving (pixel centre `u' = (u - 0.5) / 2`).
    pub(super) fn halved(self) -> Self {
        Self {
            fx: self.fx * 0.5,
            fy: self.fy * 0.5,
            skew: self.skew * 0.5,
            cx: (self.cx - 0.5) * 0.5,
            cy: (self.cy - 0.5) * 0.5,
        }
    }

    /// The pixel ray `(x, y, z)` projects to; a ray behind the camera gets an
    /// out-of-image coordinate (branch-free, so the loops calling it vectorize).
    #[inline(always)]
    pub(super) fn project(&self, x: f32, y: f32, z: f32) -> (f32, f32) {
        let iz = if z > 1e-6 { 1.0 / z } else { -1e9 };
        let (xn, yn) = (x * iz, y * iz);
        (
            self.fx * xn + self.skew * yn + self.cx,
            self.fy * yn + self.cy,
        )
    }

    /// The normalized ray `(x, y)` (at `z = 1`) through pixel `(u, v)`.
    pub(super) fn ray(&self, u: f32, v: f32) -> (f32, f32) {
        let y = (v - self.cy) / self.fy;
        ((u - self.cx - self.skew * y) / self.fx, y)
    }
}
