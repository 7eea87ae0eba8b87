//! Which terms of the readout path are estimated, and on which levels: the
//! model follows the motion's pace.

use super::state::Pose;
use super::Tracker;
use crate::shutter::{IntraFrame, INTRA_TERMS};
use crate::so3::{self, Tangent};

/// Pyramid levels (finest first) on which a rolling shutter's readout motion
/// is estimated at a fast pace (every level of the default pyramid, see
/// [`Tracker::level_terms`]); coarser levels keep the last frame's.
pub(super) const INTRA_LEVELS: usize = 4;

/// The same at a slow pace, where `phi` alone is estimated under a prior:
/// the two finest levels (see `docs/core-history.md#tracker-slow-intra-levels`).
pub(super) const SLOW_INTRA_LEVELS: usize = 2;

/// Least typical fourth-order bend of the readout path (finest-level pixels,
/// at the readout's ends, see [`Tracker::quartic_bend_px`]) at which its
/// fourth term `xi` is estimated: below it the extra term costs precision
/// where there is nothing for it to fit (see `docs/core-history.md#tracker-quartic-min-px`).
pub(super) const QUARTIC_MIN_PX: f64 = 0.05;

/// Least typical rotation across a readout (finest-level pixels) at which
/// the higher terms of the readout path are estimated (with a fast pace): a
/// path bending within a readout of less cannot be told from noise.
pub(super) const MIN_FAST_READOUT_PX: f64 = 0.5;

/// The readout path's model follows the motion's pace, measured by the lag-one
/// autocorrelation of the pose-to-pose rates, `rho = <w_j . w_(j-1)> /
/// <|w_j|^2>` (moving averages), which is `cos(2 pi f dt)` for shake at `f` Hz.
/// Below this value the motion is fast (it turns within five frames: flapping
/// wings, a motor's vibration): the rate at the last frame predicts the current
/// one poorly, and the readout path bends and twists within a readout, so
/// `phi`, `psi` and `chi` are all estimated, freely. Above it the motion is
/// slow (a hand's sway, a car's ride): only `phi` is estimated, under the
/// [`ReadoutPrior`](super::shutter_prior::ReadoutPrior) (the last rate predicts
/// it well), as the higher terms would mostly fit parallax and moving objects.
/// The value separates fast shake from a phone's sway (see
/// `docs/core-history.md#tracker-pace-switch`).
pub(super) const PACE_SWITCH: f64 = 0.3;

/// Least typical second-order bend of the readout path (finest-level pixels,
/// at the readout's ends, see [`Tracker::quadratic_bend_px`]) at which the
/// motion counts as fast whatever its pace: large, slower shake (a legged
/// robot's gait, a runner's hand) turns less from frame to frame than
/// [`PACE_SWITCH`] asks, yet its path bends within a readout, which `phi`
/// alone cannot follow (see `docs/core-history.md#tracker-min-bend-px`).
pub(super) const MIN_BEND_PX: f64 = 0.5;

/// Weight of one frame in the moving averages of [`PACE_SWITCH`].
pub(super) const PACE_GAIN: f64 = 0.05;

/// Until the pace is known (the first two frame pairs), a rolling-shutter frame
/// counts as slow, so only `phi` is estimated; it is tracked with the whole
/// path free as well, and that is kept where its residual is below this share
/// of the slow model's: fast motion's first frames need the whole path, while
/// on slow footage the higher terms fit parallax (see
/// `docs/core-history.md#tracker-start-path-gain`).
pub(super) const START_PATH_GAIN: f32 = 0.5;

impl Tracker {
    /// Whether the readout path's even terms (`psi`, and `xi`) are estimated,
    /// at the pace of the frames so far (a fast one, as `PACE_SWITCH` tells): only
    /// then is a frame's mid-readout pose less certain than a global
    /// shutter's (the centre of a fitted path trades off against its bend).
    pub fn estimates_bend(&self) -> bool {
        self.path_terms() >= 2
    }

    /// Whether the motion is fast for the readout path's model: it turns
    /// within a few frames ([`PACE_SWITCH`]), or its path bends visibly within
    /// a readout however slow its pace ([`MIN_BEND_PX`]); slow until two
    /// rates are known, but for the try with the whole path free then
    /// ([`START_PATH_GAIN`]).
    pub(super) fn fast_motion(&self) -> bool {
        if self.start_path_free {
            return true;
        }
        self.readout_motion_px()
            .is_some_and(|px| px >= MIN_FAST_READOUT_PX)
            && (self.pace.0 < PACE_SWITCH * self.pace.1
                || self.quadratic_bend_px().is_some_and(|px| px >= MIN_BEND_PX))
    }

    /// How many terms of the readout path are estimated (on the levels that
    /// estimate it): none with a global shutter, `phi` alone with a slow
    /// pace, and with a fast one `phi, psi, chi`, and `xi` where the path
    /// bends enough ([`QUARTIC_MIN_PX`]).
    pub(super) fn path_terms(&self) -> usize {
        if self.rolling.is_none() {
            0
        } else if !self.fast_motion() {
            1
        } else if self
            .quartic_bend_px()
            .is_some_and(|px| px >= QUARTIC_MIN_PX)
        {
            INTRA_TERMS
        } else {
            INTRA_TERMS - 1
        }
    }

    /// The pyramid levels (finest first) that estimate the readout path:
    /// [`INTRA_LEVELS`] at a fast pace, [`SLOW_INTRA_LEVELS`] at a slow one.
    pub(super) fn intra_levels(&self) -> usize {
        if self.fast_motion() {
            INTRA_LEVELS
        } else {
            SLOW_INTRA_LEVELS
        }
    }

    /// Each level hands the next its rotation, and the rotation absorbs what
    /// the level leaves out of the path: held at the last frame's on the coarse
    /// levels, the finest level's first step moved the rotation and the coarse
    /// levels crawled, hence the path's terms on every level at a fast pace
    /// (see `docs/core-history.md#tracker-level-terms`).
    pub(super) fn level_terms(&self, level: usize) -> usize {
        match level {
            0 => self.path_terms(),
            1 => self.path_terms().min(INTRA_TERMS - 1),
            l if l < self.intra_levels() => self.path_terms().min(1),
            _ => 0,
        }
    }

    /// The typical fourth-order bend of the readout path at the readout's
    /// ends, in finest-level pixels; `None` until two rates are known.
    ///
    /// Shake at `f` Hz, `theta(t) = A sin(2 pi f t)`, has the rate amplitude
    /// `omega = 2 pi f A`, and its path's fourth Taylor term over a readout
    /// `tau` is `tau^4 theta'''' / 24`, of size `omega tau x^3 / 24` with
    /// `x = 2 pi f tau`; at `s = 1/2` that is `1/16` of it. `omega tau` in
    /// pixels is [`Tracker::readout_motion_px`], and `2 pi f dt` is the arc
    /// cosine of the rates' lag-one autocorrelation ([`PACE_SWITCH`]).
    pub(super) fn quartic_bend_px(&self) -> Option<f64> {
        let (motion, x) = self.readout_phase()?;
        Some(motion * x.powi(3) / 384.0)
    }

    /// The typical second-order bend of the readout path at the readout's
    /// ends, in finest-level pixels (as [`Tracker::quartic_bend_px`]: the
    /// second Taylor term `tau^2 theta'' / 2` is of size `omega tau x / 2`,
    /// and `1/4` of it at `s = 1/2`); `None` until two rates are known.
    pub(super) fn quadratic_bend_px(&self) -> Option<f64> {
        let (motion, x) = self.readout_phase()?;
        Some(motion * x / 8.0)
    }

    /// The typical rotation across a readout in finest-level pixels
    /// ([`Tracker::readout_motion_px`]) and the shake's phase across it,
    /// `x = 2 pi f tau` (from the rates' lag-one autocorrelation, see
    /// [`PACE_SWITCH`]); `None` until two rates are known.
    pub(super) fn readout_phase(&self) -> Option<(f64, f64)> {
        let motion = self.readout_motion_px()?;
        if !(self.frame_dt > 0.0) {
            return None;
        }
        let rho = (self.pace.0 / self.pace.1).clamp(-1.0, 1.0);
        Some((motion, rho.acos() * self.readout_s / self.frame_dt))
    }

    /// The typical rotation across a readout, in finest-level pixels: the
    /// RMS pose-to-pose rate (the moving average of [`PACE_SWITCH`]) times the
    /// readout time times the focal length; `None` until two rates are known.
    pub(super) fn readout_motion_px(&self) -> Option<f64> {
        (self.pace.1 > 0.0)
            .then(|| self.pace.1.sqrt() * self.readout_s * self.base.fx.max(self.base.fy) as f64)
    }

    /// A fresh start for the readout path before the first level that estimates
    /// it, under fast motion: `phi` from the rate between the last frame and
    /// this frame's rotation as the coarse levels found it, and no higher
    /// terms. At 12-20 Hz shake the last frame's path (the start otherwise) is
    /// a poor guess, since the rates' lag-one autocorrelation is negative
    /// there, while this rate is centred only half a frame earlier (see
    /// `docs/core-history.md#tracker-seed-intra`). `None`: keep the start
    /// (global shutter, slow motion, the first frame pair).
    pub(super) fn seed_intra(&self, pose: &Pose, dt: f64) -> Option<IntraFrame> {
        let (_, r_prev) = self.last?;
        if self.rolling.is_none() || !self.fast_motion() || !(dt.is_finite() && dt > 0.0) {
            return None;
        }
        let rate = so3::body_rate(&r_prev, &(self.r_0k * pose.r), dt);
        Some(self.path_of_rate(&rate).plus(&self.gauge_tpl, 1.0))
    }

    /// The readout path a constant body rate `rate` draws: `phi = rate tau`,
    /// no higher terms.
    pub(super) fn path_of_rate(&self, rate: &Tangent) -> IntraFrame {
        IntraFrame {
            phi: rate * self.readout_s,
            ..IntraFrame::ZERO
        }
    }
}
