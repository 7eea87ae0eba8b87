//! The gauge of the readout motion.

use super::Tracker;
use crate::shutter::{IntraFrame, INTRA_TERMS};
use crate::so3::Tangent;

/// First block of the gauge check, frames.
pub(super) const GAUGE_FIRST_BLOCK: usize = 8;

/// Longest block of the gauge check, frames.
pub(super) const GAUGE_BLOCK: usize = 64;

impl Tracker {
    /// Whether the readout paths reported ([`Tracker::intra`]) are in the
    /// absolute gauge, checked against time at least once (see `Gauge`);
    /// before that, in the first frame's: each is the difference between
    /// the frame's path and the first frame's, whose own was unknown (zero).
    pub fn gauge_known(&self) -> bool {
        self.gauge_settled
    }

    /// The sum of the corrections made to the readout paths' gauge so far
    /// (the block check's and [`Tracker::regauge_template`]'s): each moved
    /// every later path reported by minus itself. A caller that shows the
    /// paths can ease the change in over a few frames instead of jumping
    /// ([`crate::shutter::GaugeEase`]).
    pub fn gauge_corrections(&self) -> IntraFrame {
        self.gauge_corrections
    }

    /// If the last frame became the template (rectified with its own path),
    /// rectifies it again with that path less `error`: the gauge error a
    /// trajectory through the recent frames found
    /// ([`crate::shutter::TrajectorySmoother::path_offset`]). From then on the
    /// corrections keep the gauge, so the block check restarts (`Gauge`).
    ///
    /// The block check averages `phi - tau omega` over 8-64 frames and is
    /// noisy and late, and a template rectified with a path off by `c` biases
    /// every frame aligned to it by about `|a| |c| / 2` (see
    /// `Tracker::settle_gauge`; see `docs/core-history.md#tracker-regauge-template`).
    pub fn regauge_template(&mut self, error: &IntraFrame) {
        if self.frames_since_reset != 0 || self.tpl_path != self.intra || self.rolling.is_none() {
            return;
        }
        let path = self.intra.plus(error, -1.0);
        self.gauge_corrections = self.gauge_corrections.plus(error, 1.0);
        self.intra = path;
        self.rectify_template_again(path);
        self.gauge.sums = [Tangent::zeros(); INTRA_TERMS];
        self.gauge.count = 0;
    }

    /// Adds the last frame to the gauge check; at the end of a block, removes
    /// the gauge error from this frame's readout motion and from every later
    /// estimate against the current template (see [`Gauge`]) and returns true.
    pub(super) fn check_gauge(&mut self) -> bool {
        let g = &mut self.gauge;
        let mut terms = self.intra.terms();
        terms[0] -= self.rate * self.readout_s;
        for (sum, t) in g.sums.iter_mut().zip(terms) {
            *sum += t;
        }
        g.count += 1;
        if g.count < g.block.max(GAUGE_FIRST_BLOCK) {
            return false;
        }
        let c = IntraFrame::from_terms(g.sums.map(|sum| sum / g.count as f64));
        g.block = (g.count * 2).min(GAUGE_BLOCK);
        g.sums = [Tangent::zeros(); INTRA_TERMS];
        g.count = 0;
        self.intra = self.intra.plus(&c, -1.0);
        self.gauge_tpl = self.gauge_tpl.plus(&c, 1.0);
        self.gauge_corrections = self.gauge_corrections.plus(&c, 1.0);
        true
    }

    /// After a correction of the gauge at a fast pace, rectifies the current
    /// template again with its own readout path as now known, instead of the
    /// one it was given (zero for the first frame's, which is held until the
    /// first correction).
    ///
    /// Only differences of readout motion are seen to first order (see
    /// [`Gauge`]), but the rotations do not commute: a template rectified with
    /// a path off by `c` biases the rotation of every frame aligned to it by
    /// about `|a| |c| / 2` (`a` the path; `exp(a - c) != exp(-c) exp(a)`). The
    /// first template's path is wholly unknown, and that bias passed down the
    /// chain of templates as a lasting orientation error (see
    /// `docs/core-history.md#tracker-settle-gauge`).
    pub(super) fn settle_gauge(&mut self) {
        if !self.fast_motion() {
            // At a slow pace the readout path is small and held near the rate's
            // prediction (see [`ReadoutPrior`]): there is little to correct,
            // and holding a template longer only lets parallax in (see
            // `docs/core-history.md#tracker-settle-gauge-slow`).
            self.gauge_settled = true;
            return;
        }
        if !self.gauge_settled {
            // The first template is kept for `n_track` more frames, so that
            // the next one's pose comes from the corrected template.
            self.gauge_settled = true;
            self.frames_since_reset = 0;
        }
        // The template was rectified with `tpl_path`; its estimates since are
        // off by `gauge_tpl`, so its own path is `tpl_path - gauge_tpl`.
        let path = self.tpl_path.plus(&self.gauge_tpl, -1.0);
        self.gauge_tpl = IntraFrame::ZERO;
        self.rectify_template_again(path);
    }
}
