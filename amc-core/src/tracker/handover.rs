//! Template handover: the frame after each template reset is tracked against
//! the outgoing template too, and the new template's orientation is set so
//! that the two agree on it ([`Tracker::hand_over`]). Every template carries
//! its own small bias into all the frames aligned to it; handed over, that
//! bias no longer steps the orientation at each reset, so it neither shows
//! as a jump between two frames nor adds up, template after template.

use super::recover::suspect;
use super::state::Handover;
use super::state::Pose;
use super::Tracker;
use crate::pyramid::Pyramid;
use crate::so3;

impl Tracker {
    /// Tracks the first frame after a reset against the outgoing template
    /// as well, starting from `pose` (its pose against the new one), and
    /// moves the new template's orientation so that both give the frame the
    /// same orientation; returns the Gauss-Newton iterations spent. Nothing
    /// moves when the outgoing template tracks the frame badly.
    ///
    /// A template's orientation is its frame's estimate, and every frame
    /// aligned to the template inherits that estimate's error, plus a bias of
    /// the template's own: with a rolling shutter the error of the path it
    /// was rectified with (rotations do not commute, so a path off by `c`
    /// turns every frame aligned to it by about `|a| |c| / 2`), with any
    /// shutter what its texture and sampling make of the rotation. Both are
    /// common to the template's frames and cancel between two of them, but
    /// at a reset they change at once: the first frame after it stepped, and
    /// the steps added up. Handed over, the new template continues the
    /// outgoing one's orientation, measured on a frame both see, for one more
    /// frame's tracking per template (see `docs/core-history.md#tracker-handover`).
    pub(super) fn hand_over(&mut self, pyr: &Pyramid, pose: &Pose, dt: f64, old: Handover) -> u32 {
        // The start: this frame's pose and path, taken to the outgoing
        // template's orientation and gauge.
        let start = Pose {
            r: old.r_0k.transpose() * self.r_0k * pose.r,
            intra: pose
                .intra
                .plus(&self.gauge_tpl, -1.0)
                .plus(&old.gauge_tpl, 1.0),
        };
        std::mem::swap(&mut self.template, &mut self.outgoing);
        let gauge_tpl = std::mem::replace(&mut self.gauge_tpl, old.gauge_tpl);
        let mut warm = std::mem::take(&mut self.handover_warm);
        let (seen, info) = self.coarse_to_fine(pyr, start, dt, &mut warm);
        self.handover_warm = warm;
        self.gauge_tpl = gauge_tpl;
        std::mem::swap(&mut self.template, &mut self.outgoing);
        if !info.lost && !suspect(&info, self.typical_residual) {
            let r_0j = old.r_0k * seen.r;
            self.r_0k = so3::renormalize(&(r_0j * pose.r.transpose()));
        }
        info.iterations
    }
}
