//! Fixtures shared by the rolling-shutter tests and the warper's: a pinhole and
//! a fisheye camera, and a readout motion with every term of the path.

use super::IntraFrame;
use crate::camera::CameraModel;
use crate::so3::Tangent;

/// A 90 deg pinhole and a 150 deg fisheye, both 320x180.
pub(crate) fn cameras() -> [CameraModel; 2] {
    [
        CameraModel::pinhole_hfov(320, 180, 90.0).unwrap(),
        CameraModel::fisheye_hfov(320, 180, 150.0, [0.05, -0.01, 0.002, -0.0005]).unwrap(),
    ]
}

/// A readout motion with all four terms of the path (rad).
pub(crate) fn readout_motion() -> IntraFrame {
    IntraFrame {
        phi: Tangent::new(0.08, -0.12, 0.05),
        psi: Tangent::new(-0.02, 0.03, 0.01),
        chi: Tangent::new(0.01, -0.005, 0.004),
        xi: Tangent::new(-0.004, 0.002, 0.003),
    }
}
