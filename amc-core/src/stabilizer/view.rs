//! The view and framing steps of an output: where the view looks (by the
//! mode), and the zoom that shows no border, the view pulled toward the
//! camera where it would need more.

use super::params::StabilizerParams;
use super::rendering::Rendering;
use super::Buffered;
use crate::framing::{pull_view, view_need, Zoom};
use crate::so3::Rot;
use crate::view::{backward_pass, Mode};
use std::collections::VecDeque;

impl Rendering {
    /// The view of the output at ring position `pos`, by the mode: the
    /// camera's own (none), the smoothed path (stabilize), the held saccade
    /// view or the first frame's (lock).
    pub(super) fn view(
        &mut self,
        ring: &VecDeque<Buffered>,
        params: &StabilizerParams,
        pos: usize,
    ) -> Rot {
        let cur = &ring[pos];
        let r_est = cur.r_est;
        match params.view.mode {
            Mode::None => r_est,
            Mode::Stabilize => {
                let filtered = if params.view.lookahead == 0 {
                    cur.view_fwd
                } else {
                    self.window.clear();
                    self.window
                        .extend(ring.iter().skip(pos).map(|b| (b.t, b.view_fwd)));
                    backward_pass(&params.view, &self.window)
                };
                params.view.roll.apply(&filtered, &r_est)
            }
            Mode::Saccade => *self.saccade_view.get_or_insert(r_est),
            Mode::Lock => *self.locked_view.get_or_insert(r_est),
        }
    }

    /// Framing: the zoom of output `j` (its frame taken at `t`, estimated at
    /// `r_est`), with `r_view` pulled toward the camera where it would need
    /// more; and whether a saccade is due (saccade mode, a border would show).
    pub(super) fn frame(
        &mut self,
        params: &StabilizerParams,
        j: u64,
        t: f64,
        r_est: &Rot,
        r_view: &mut Rot,
    ) -> (f64, bool) {
        let mode = params.view.mode;
        let mut saccade = false;
        let zoomed = params.framing.zoom != Zoom::None;
        let zoom = if !zoomed {
            1.0
        } else if mode == Mode::None {
            if params.shutter.is_rolling() {
                // Rows rendered at their own orientations no longer fill the
                // frame: the least zoom that shows no border, per frame.
                let need = self.need(r_view);
                self.camera_zoom.max(need).min(params.framing.max_zoom())
            } else {
                self.camera_zoom
            }
        } else {
            let need = self.need(r_view);
            self.max_need = self.max_need.max(need);
            let z = self.framer.next(t, need);
            if need > z {
                if mode == Mode::Saccade && j > 0 {
                    // A border would show: re-centre now, whatever the refractory period.
                    saccade = true;
                } else {
                    let (pulled, _) = pull_view(
                        &self.src_cam,
                        &self.border,
                        &self.window_rots,
                        self.warper.readout_rows(),
                        r_view,
                        r_est,
                        z,
                        &mut self.need_rots,
                    );
                    *r_view = pulled;
                }
            }
            z
        };
        (zoom, saccade)
    }

    /// The zoom at which `view` shows no border with the averaged frames
    /// `self.window_rots`.
    fn need(&mut self, view: &Rot) -> f64 {
        view_need(
            &self.src_cam,
            &self.border,
            &self.window_rots,
            self.warper.readout_rows(),
            view,
            &mut self.need_rots,
        )
    }
}
