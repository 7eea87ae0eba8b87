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

/// Terms of the readout path's polynomial.
pub const INTRA_TERMS: usize = 4;

/// The rotation of a camera during one frame's readout, relative to its
/// mid-readout pose: `R(s) = R_mid exp(s phi + s^2 psi + s^3 chi + s^4 xi)` for readout
/// fraction `s` (see the module's docs). Zero for a global shutter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct IntraFrame {
    /// Rotation across the readout (radians, the frame's camera axes):
    /// the readout time times the angular velocity at mid-readout.
    pub phi: Tangent,
    /// Bend of the readout path (radians): the readout time squared over two
    /// times the angular acceleration.
    pub psi: Tangent,
    /// Third-order term (radians): the readout time cubed over six times the
    /// angular jerk. At 12-20 Hz shake a 15 ms readout spans a quarter of a
    /// period, and without it the path's S-shape leaks into `phi`.
    pub chi: Tangent,
    /// Fourth-order term (radians): the readout time to the fourth over 24
    /// times the angular snap; fast shake through a long readout needs it
    /// (see `docs/core-history.md#shutter-xi`).
    #[serde(default)]
    pub xi: Tangent,
}

impl IntraFrame {
    /// No motion during the readout (a global shutter).
    pub const ZERO: IntraFrame = IntraFrame {
        phi: Tangent::new(0.0, 0.0, 0.0),
        psi: Tangent::new(0.0, 0.0, 0.0),
        chi: Tangent::new(0.0, 0.0, 0.0),
        xi: Tangent::new(0.0, 0.0, 0.0),
    };

    /// The terms `phi, psi, chi, xi` (coefficients of `s, s^2, s^3, s^4`).
    pub fn terms(&self) -> [Tangent; INTRA_TERMS] {
        [self.phi, self.psi, self.chi, self.xi]
    }

    /// The motion with these terms (coefficients of `s, s^2, s^3, s^4`).
    pub fn from_terms([phi, psi, chi, xi]: [Tangent; INTRA_TERMS]) -> Self {
        Self { phi, psi, chi, xi }
    }

    /// The motion with only its first `n` terms (the others zero).
    pub fn truncated(&self, n: usize) -> Self {
        let t = self.terms();
        Self::from_terms(std::array::from_fn(|k| {
            if k < n {
                t[k]
            } else {
                Tangent::zeros()
            }
        }))
    }

    /// `self + scale other`, term by term.
    pub fn plus(&self, other: &IntraFrame, scale: f64) -> Self {
        let (a, b) = (self.terms(), other.terms());
        Self::from_terms(std::array::from_fn(|k| a[k] + b[k] * scale))
    }

    /// True for a global shutter's (exactly zero) motion.
    pub fn is_zero(&self) -> bool {
        self.terms().iter().all(|t| *t == Tangent::zeros())
    }

    /// The rotation vector of `R_mid^T R(s)`: `s phi + s^2 psi + s^3 chi + s^4 xi`.
    #[inline]
    pub fn at(&self, s: f64) -> Tangent {
        (self.phi + (self.psi + (self.chi + self.xi * s) * s) * s) * s
    }

    /// `R_mid^T R(s)`.
    pub fn rotation_at(&self, s: f64) -> Rot {
        so3::exp(&self.at(s))
    }
}
