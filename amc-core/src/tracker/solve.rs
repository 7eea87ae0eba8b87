//! The estimate of one frame: Gauss-Newton with backtracking at each level,
//! coarse to fine.
//!
//! Robustness:
//! * Backtracking line search on the mean robust loss: a step is halved until the
//!   loss does not increase, so the estimate never gets worse.
//! * Coarse-to-fine pyramid: a 2x2 box pyramid down to ~40 px wide gives a
//!   basin of tens of pixels at full resolution (300 deg/s at 60 fps).

use super::eval::Eval;
use super::params::TrackInfo;
use super::rolling::MATRIX_REFRESH_PX;
use super::shutter_prior::ReadoutPrior;
use super::state::Pose;
use super::state::WarmStart;
use super::Tracker;
use crate::image::GrayImage;
use crate::pyramid::Pyramid;

/// Line-search halvings before a level gives up (2^-8 of a step is negligible).
pub(super) const MAX_BACKTRACK: usize = 8;

/// Convergence threshold of coarse levels relative to the finest level's.
pub(super) const COARSE_TOLERANCE_FACTOR: f64 = 20.0;

/// Fewer valid template pixels than this share means the frame is lost at that level.
pub(super) const MIN_VALID_SHARE: f32 = 0.15;

impl Tracker {
    /// Runs all levels from `pose`, returning the estimate and its quality.
    pub(super) fn coarse_to_fine(
        &self,
        pyr: &Pyramid,
        mut pose: Pose,
        dt: f64,
        warm_start: &mut WarmStart,
    ) -> (Pose, TrackInfo) {
        let mut info = TrackInfo::default();
        for level in (0..self.n_levels).rev() {
            if level + 1 == self.intra_levels().min(self.n_levels) {
                if let Some(intra) = self.seed_intra(&pose, dt) {
                    pose.intra = intra;
                }
            }
            let (p_new, final_eval, iters) =
                self.refine(level, &pyr.levels[level], pose, warm_start);
            pose = p_new;
            info.iterations += iters;
            if level == 0 {
                let n_tpl = self.template[0].xs.len().max(1) as f32;
                info.valid_fraction = final_eval.n as f32 / n_tpl;
                info.rms_residual = if final_eval.n > 0 {
                    (final_eval.sq / final_eval.n as f64).sqrt() as f32
                } else {
                    f32::NAN
                };
                info.lost = info.valid_fraction < MIN_VALID_SHARE;
            }
        }
        (pose, info)
    }

    /// Iterates Gauss-Newton with backtracking at one level.
    ///
    /// A step shorter than the level's convergence threshold ends the level
    /// without being tried: near the optimum such steps are noise, and testing
    /// them (with halvings) would cost full passes for nothing. With a rolling
    /// shutter the readout motion is estimated on the finest
    /// [`Tracker::intra_levels`] levels (coarser ones have too few rows to
    /// see it).
    pub(super) fn refine(
        &self,
        level: usize,
        img: &GrayImage,
        mut pose: Pose,
        warm_start: &mut WarmStart,
    ) -> (Pose, Eval, u32) {
        let tpl = &self.template[level];
        let min_valid = ((tpl.xs.len() as f32) * MIN_VALID_SHARE).max(8.0) as u32;
        let f_level = tpl.k.map_or(1.0, |k| k.fx.max(k.fy)) as f64;
        let intra = self.rolling.is_some() && level < self.intra_levels();
        let mut prior = None;
        // Coarse levels only need to land inside the next level's basin.
        let tol = self.params.convergence_px
            * if level == 0 {
                1.0
            } else {
                COARSE_TOLERANCE_FACTOR
            };
        warm_start.valid = false;
        let mut cur = self.evaluate(level, img, &pose, Some(&mut *warm_start));
        let fast = self.fast_motion();
        if intra && !fast {
            prior = Some(ReadoutPrior {
                mean: self.prior_mean,
                weight: self.prior_strength() * (cur.h[0] + cur.h[3] + cur.h[5]) / 3.0,
            });
        }
        let terms = self.level_terms(level);
        // The objective: mean robust loss, plus the prior's share.
        let objective = |e: &Eval, p: &Pose| {
            e.mean_loss()
                + prior
                    .as_ref()
                    .map_or(0.0, |q| q.energy(&p.intra) / e.n.max(1) as f64)
        };
        let mut cur_obj = objective(&cur, &pose);
        let mut iters = 0;
        for _ in 0..self.params.max_iterations {
            if cur.n < min_valid {
                break;
            }
            let Some(step) = cur.pose_step(&pose, intra, terms, prior.as_ref()) else {
                break;
            };
            let step_px = step.angle() * f_level;
            if step_px < tol {
                break;
            }
            iters += 1;
            let mut s = 1.0;
            let mut accepted = false;
            for _ in 0..MAX_BACKTRACK {
                let cand = step.apply(&pose, s);
                warm_start.refresh = step_px * s > MATRIX_REFRESH_PX;
                let e = self.evaluate(level, img, &cand, Some(&mut *warm_start));
                let obj = objective(&e, &cand);
                if e.n >= min_valid && obj <= cur_obj {
                    pose = cand;
                    cur = e;
                    cur_obj = obj;
                    accepted = true;
                    break;
                }
                s *= 0.5;
                if step_px * s < tol {
                    break;
                }
            }
            if !accepted || step_px * s < tol {
                break;
            }
        }
        (pose, cur, iters)
    }
}
