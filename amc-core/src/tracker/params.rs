//! The tracker's parameters and what it reports per frame.

use crate::error::{check_range, AmcError};
use serde::{Deserialize, Serialize};

/// Parameters of the rotation tracker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerParams {
    /// Template reset period, in frames (`N_track`; paper: 5). Range 1..=1000.
    pub n_track: usize,
    /// Maximum number of pyramid levels (1 = single scale). Levels stop before a
    /// side would drop under 12 px. Range 1..=8.
    pub pyramid_levels: usize,
    /// Maximum number of template pixels per pyramid level. Range 64..=1_000_000.
    pub max_points: usize,
    /// Huber threshold on the intensity residual, in intensity units
    /// (intensities are in `[0, 1]`; 0.04 ~ 10/255). Range 0.001..=1.
    pub huber_delta: f64,
    /// Maximum Gauss-Newton iterations per pyramid level. Range 1..=200.
    pub max_iterations: usize,
    /// Convergence threshold: stop a level when the step moves pixels of that
    /// level by less than this, in pixels. Range 1e-5..=1.
    pub convergence_px: f64,
    /// Try a constant angular-velocity prediction as a warm start.
    pub predict: bool,
    /// Detect and ignore camera-fixed image regions (dashboards, overlays). Off
    /// by default: opt-in until footage shows a benefit (see
    /// `docs/core-history.md#tracker-reject-static`).
    pub reject_static: bool,
}

impl Default for TrackerParams {
    fn default() -> Self {
        Self {
            n_track: 5,
            pyramid_levels: 4,
            max_points: 3000,
            huber_delta: 0.04,
            max_iterations: 30,
            convergence_px: 0.002,
            predict: true,
            reject_static: false,
        }
    }
}

impl TrackerParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<(), AmcError> {
        if !(1..=1000).contains(&self.n_track) {
            return Err(AmcError::invalid(
                "n_track",
                self.n_track,
                "1..=1000 frames",
            ));
        }
        if !(1..=8).contains(&self.pyramid_levels) {
            return Err(AmcError::invalid(
                "pyramid_levels",
                self.pyramid_levels,
                "1..=8",
            ));
        }
        if !(64..=1_000_000).contains(&self.max_points) {
            return Err(AmcError::invalid(
                "max_points",
                self.max_points,
                "64..=1000000",
            ));
        }
        check_range(
            "huber_delta",
            self.huber_delta,
            0.001,
            1.0,
            "0.001..=1 (intensity units)",
        )?;
        if !(1..=200).contains(&self.max_iterations) {
            return Err(AmcError::invalid(
                "max_iterations",
                self.max_iterations,
                "1..=200",
            ));
        }
        check_range(
            "convergence_px",
            self.convergence_px,
            1e-5,
            1.0,
            "0.00001..=1 pixels",
        )?;
        Ok(())
    }
}

/// Quality of one frame's tracking.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackInfo {
    /// Gauss-Newton iterations over all levels.
    pub iterations: u32,
    /// RMS intensity residual at the finest level (intensity units).
    pub rms_residual: f32,
    /// Share of the finest level's template pixels that were valid.
    pub valid_fraction: f32,
    /// True when the template was replaced by this frame after tracking it.
    pub template_reset: bool,
    /// True when fewer than 15% of template pixels were valid (the estimate is a guess).
    pub lost: bool,
}
