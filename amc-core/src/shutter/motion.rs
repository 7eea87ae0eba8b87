//! A frame's motion during its readout.

use crate::so3::{self, Rot, Tangent};
use serde::{Deserialize, Serialize};

/// The readout fraction of sensor row `y` (pixel centres at integers) of a
/// frame `height` rows high: `y / H - 1/2`, so the first row is read at
/// `-1/2`, the middle row at about 0 and the last at `1/2 - 1/H`.
#[inline]
pub fn row_fraction(y: f64, height: usize) -> f64 {
    y / height.max(1) as f64 - 0.5
}

/// The rotation of a camera during one frame's readout, relative to its
/// mid-readout pose: `R(s) = R_mid exp(s phi + s^2 psi)` for readout fraction
/// `s` (see the module's docs). Zero for a global shutter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct IntraFrame {
    /// Rotation across the readout (radians, the frame's camera axes):
    /// the readout time times the angular velocity at mid-readout.
    pub phi: Tangent,
    /// Bend of the readout path (radians): the readout time squared over two
    /// times the angular acceleration.
    pub psi: Tangent,
}

impl IntraFrame {
    /// No motion during the readout (a global shutter).
    pub const ZERO: IntraFrame = IntraFrame {
        phi: Tangent::new(0.0, 0.0, 0.0),
        psi: Tangent::new(0.0, 0.0, 0.0),
    };

    /// True for a global shutter's (exactly zero) motion.
    pub fn is_zero(&self) -> bool {
        self.phi == Tangent::zeros() && self.psi == Tangent::zeros()
    }

    /// The rotation vector of `R_mid^T R(s)`: `s phi + s^2 psi`.
    #[inline]
    pub fn at(&self, s: f64) -> Tangent {
        self.phi * s + self.psi * (s * s)
    }

    /// `R_mid^T R(s)`.
    pub fn rotation_at(&self, s: f64) -> Rot {
        so3::exp(&self.at(s))
    }
}
