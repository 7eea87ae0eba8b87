//! The prior on a frame's readout path.

use super::Tracker;
use crate::shutter::{IntraFrame, INTRA_TERMS};
use crate::so3::Tangent;

/// A Gaussian prior on a frame's readout path, in the template's gauge:
/// `phi` near the readout time times the last pose-to-pose rate, the higher
/// terms near zero. It costs `weight |theta - mean|^2 / 2` (intensity units
/// squared, the robust loss's), and `weight` is [`READOUT_PRIOR`] times the
/// information the level's points carry about one rotation axis: the data
/// outweigh it wherever they see the readout path (shake of 12-20 Hz filmed
/// through a 10-20 ms readout), and it holds the path where they barely do (a
/// hand's slow sway, a car's parallax and a scene that moves on its own).
#[derive(Clone, Copy, Debug)]
pub(super) struct ReadoutPrior {
    pub(super) mean: IntraFrame,
    pub(super) weight: f64,
}

impl ReadoutPrior {
    /// `theta - mean`, term by term.
    pub(super) fn deviation(&self, intra: &IntraFrame) -> [Tangent; INTRA_TERMS] {
        intra.plus(&self.mean, -1.0).terms()
    }

    /// `weight |theta - mean|^2 / 2`.
    pub(super) fn energy(&self, intra: &IntraFrame) -> f64 {
        0.5 * self.weight
            * self
                .deviation(intra)
                .iter()
                .map(|d| d.norm_squared())
                .sum::<f64>()
    }
}

/// Strength of the [`ReadoutPrior`], relative to the data's information
/// about one rotation axis, where the readout motion is well observed (see
/// [`OBSERVABLE_READOUT_PX`]).
pub(super) const READOUT_PRIOR: f64 = 1e-3;

/// Rotation across a readout (finest-level pixels, typical) from which the data
/// pin `phi` down against what else they fit. Below it the prior grows: slow
/// forward flight shows far more looming than readout motion, and looming's
/// vertical half is what `phi_x` does to the rows (see
/// `docs/core-history.md#tracker-observable-readout-px`).
pub(super) const OBSERVABLE_READOUT_PX: f64 = 2.0;

impl Tracker {
    /// Whether the readout motion is known to be too small to be observed
    /// (see [`OBSERVABLE_READOUT_PX`]).
    pub(super) fn readout_unobservable(&self) -> bool {
        self.readout_motion_px()
            .is_some_and(|px| px < OBSERVABLE_READOUT_PX)
    }

    /// The weight of the [`ReadoutPrior`] per unit of the data's information:
    /// [`READOUT_PRIOR`] where the readout motion spans
    /// [`OBSERVABLE_READOUT_PX`] or more (or is not known yet), growing as the
    /// square of the shortfall below it (the data's pull on `phi` shrinks with
    /// the motion it has to see, while what else it fits, looming and
    /// parallax, does not).
    pub(super) fn prior_strength(&self) -> f64 {
        let seen = self
            .readout_motion_px()
            .map_or(1.0, |px| px / OBSERVABLE_READOUT_PX);
        READOUT_PRIOR / seen.clamp(1e-2, 1.0).powi(2)
    }
}
