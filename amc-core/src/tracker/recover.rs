//! Recovery from a wrong local minimum: when a frame's final residual is far
//! above the typical residual (a wrong local minimum, e.g. a 6 deg jerk), a
//! grid of pan/tilt offsets is scored at the coarsest level, the best is
//! refined coarse to fine, and the result with the lower residual is kept. A
//! frame that still tracks badly never becomes the template (the reset waits
//! for a good frame), so one bad frame cannot bake its error into every later
//! estimate.

use super::params::TrackInfo;
use super::solve::MIN_VALID_SHARE;
use super::state::Pose;
use super::state::WarmStart;
use super::Tracker;
use crate::pyramid::Pyramid;
use crate::so3::{self, Tangent};

/// A frame is suspect when its RMS residual exceeds this multiple of the typical one.
pub(super) const SUSPECT_RATIO: f32 = 2.5;

/// ...and this absolute floor (intensity units): noise-free clips have tiny residuals.
pub(super) const SUSPECT_FLOOR: f32 = 0.02;

/// Recovery grid: offsets `-R..=R` steps on each of the pan and tilt axes.
pub(super) const RECOVERY_RADIUS: i32 = 3;

/// Recovery grid step, in pixels of the coarsest level (inside its basin).
pub(super) const RECOVERY_STEP_PX: f64 = 1.5;

/// Whether a frame's final residual is far above the `typical` one (a wrong
/// local minimum, see [`SUSPECT_RATIO`]).
pub(super) fn suspect(info: &TrackInfo, typical: Option<f32>) -> bool {
    let limit = typical.map_or(f32::INFINITY, |t| (SUSPECT_RATIO * t).max(SUSPECT_FLOOR));
    !(info.rms_residual <= limit)
}

impl Tracker {
    /// Recovery from a wrong minimum: scores a pan/tilt grid around `center` at
    /// the coarsest level and refines the best point at all levels.
    pub(super) fn recover(
        &self,
        pyr: &Pyramid,
        center: Pose,
        dt: f64,
        warm_start: &mut WarmStart,
    ) -> (Pose, TrackInfo) {
        let coarsest = self.n_levels - 1;
        let img = &pyr.levels[coarsest];
        let f = self.template[coarsest].k.map_or(1.0, |k| k.fx.max(k.fy)) as f64;
        let step = RECOVERY_STEP_PX / f;
        let min_valid = ((self.template[coarsest].xs.len() as f32) * MIN_VALID_SHARE) as u32;
        let mut best = (f64::INFINITY, center);
        for i in -RECOVERY_RADIUS..=RECOVERY_RADIUS {
            for j in -RECOVERY_RADIUS..=RECOVERY_RADIUS {
                // Offsets about the template camera's y (pan) and x (tilt) axes.
                let cand = Pose {
                    r: so3::exp(&Tangent::new(j as f64 * step, i as f64 * step, 0.0)) * center.r,
                    intra: center.intra,
                };
                let e = self.evaluate(coarsest, img, &cand, None);
                if e.n > min_valid && e.mean_loss() < best.0 {
                    best = (e.mean_loss(), cand);
                }
            }
        }
        self.coarse_to_fine(pyr, best.1, dt, warm_start)
    }
}
