//! The rendering stage: the ring's frames in, stabilized frames out.

use super::buffered::Buffered;
use super::params::StabilizerParams;
use super::telemetry::Telemetry;
use crate::camera::CameraModel;
use crate::framing::{zoom_matrix, Border, Framer, Zoom};
use crate::image::Frame;
use crate::render::{Accumulator, DeghostLevel, WarpedFrame, Warper};
use crate::so3::{self, Rot};
use crate::view::Mode;
use std::collections::VecDeque;

/// The rendering stage: the ring's frames in, stabilized frames out. Apart
/// from [`Tracking`](super::tracking::Tracking) so that the two can run at once (see
/// [`Stabilizer::set_pipelined`](super::Stabilizer::set_pipelined)).
pub(super) struct Rendering {
    /// Renders colour frames, or the Y plane of planar ones.
    pub(super) warper: Warper,
    /// Renders the U and V planes of 4:2:0 frames (the chroma cameras).
    pub(super) chroma: Warper,
    /// Coverage of the chroma planes (reused; the luma's is reported).
    pub(super) chroma_cov: Vec<u8>,
    pub(super) out_cam: CameraModel,
    pub(super) saccade_view: Option<Rot>,
    pub(super) slots: VecDeque<WarpedFrame>,
    pub(super) spare_slots: Vec<WarpedFrame>,
    pub(super) acc: Accumulator,
    /// Ghost-free averaging of the saccade slots (the running sum `acc` is the
    /// plain average; the weights change with every newest frame, so the
    /// weighted one is merged from the slots per output, with the warper's
    /// [`Warper::deghost`]): its weighted sums and weights' sums (reused).
    pub(super) merged_sum: Vec<u32>,
    pub(super) merged_weight: Vec<u32>,
    pub(super) rotations: Vec<nalgebra::Matrix3<f64>>,
    /// Forward-filtered views of the lookahead window (reused).
    pub(super) window: Vec<(f64, Rot)>,
    pub(super) output: Frame,
    pub(super) next_out: u64,
    pub(super) last_shown: Option<(f64, Rot, Rot)>,
    pub(super) last_saccade: Option<u64>,
    /// The source camera (the one the frames were taken with).
    pub(super) src_cam: CameraModel,
    /// The zoom over time.
    pub(super) framer: Framer,
    /// The output's border, for the framing's coverage test.
    pub(super) border: Border,
    /// Orientations of the averaged frames (reused).
    pub(super) window_rots: Vec<Rot>,
    /// Rotations of the framing's coverage test (reused).
    pub(super) need_rots: Vec<nalgebra::Matrix3<f64>>,
    /// Whether pixels are rendered (off: views and zoom needs only).
    pub(super) render: bool,
    /// Tracking only: no view, framing or pixels, the tracker's telemetry
    /// alone ([`Stabilizer::set_tracking_only`](super::Stabilizer::set_tracking_only)).
    pub(super) tracking_only: bool,
    /// Which outputs this stabilizer renders: output `j` when `j % share.0 ==
    /// share.1` ([`Stabilizer::set_render_share`](super::Stabilizer::set_render_share)); `(1, 0)`: every one.
    pub(super) share: (u64, u64),
    /// Lock mode's view: the first frame's orientation.
    pub(super) locked_view: Option<Rot>,
    /// The zoom of mode none (the camera's own view, the same on every frame).
    pub(super) camera_zoom: f64,
    /// Highest need of a smoothed view so far.
    pub(super) max_need: f64,
}

impl Rendering {
    /// Renders output frame `self.next_out` from `ring` (frames of size `src`),
    /// step by step: its window of frames, its view, its zoom and framing,
    /// its pixels (unless another stabilizer renders them), its telemetry.
    pub(super) fn render_next(
        &mut self,
        ring: &VecDeque<Buffered>,
        params: &StabilizerParams,
        src: (usize, usize),
    ) -> Telemetry {
        let j = self.next_out;
        self.next_out += 1;
        if self.tracking_only {
            let pos = ring.iter().position(|b| b.index == j).unwrap_or(0);
            let shown = Shown {
                frames_averaged: 1,
                valid_fraction: 0.0,
                saccade: false,
                zoom: 1.0,
                uncovered: 0,
            };
            let r_est = ring[pos].r_est;
            return self.telemetry(&ring[pos], params, j, &r_est, shown);
        }
        let render = self.render && j % self.share.0 == self.share.1;
        let (first, pos) = self.window(ring, params, j);
        if params.render.deghost == DeghostLevel::Auto {
            // The threshold in force when the newest frame arrived.
            self.warper.set_deghost(ring[pos].deghost);
            self.chroma.set_deghost(ring[pos].deghost);
        }
        let r_est = ring[pos].r_est;
        let mut r_view = self.view(ring, params, pos);
        let (zoom, mut saccade) = self.frame(params, j, ring[pos].t, &r_est, &mut r_view);
        let zinv = zoom_matrix(zoom);
        let valid_fraction = if !render {
            // First pass of `zoom = static`, or another stabilizer's share:
            // views and needs only.
            0.0
        } else if params.view.mode == Mode::Saccade {
            let window = (first, pos);
            self.render_saccade(
                ring,
                params,
                src,
                j,
                window,
                &mut r_view,
                &mut saccade,
                &zinv,
            )
        } else {
            self.render_average(ring, src, (first, pos), &r_view, &zinv)
        };
        let r_view = if saccade { r_est } else { r_view };
        let uncovered = if render {
            let (ow, oh) = (self.out_cam.width, self.out_cam.height);
            let n = (ow * oh).min(self.acc.count.len());
            crate::lanes::count_byte(&self.acc.count[..n], 0) as u64
        } else {
            0
        };
        let shown = Shown {
            frames_averaged: pos + 1 - first,
            valid_fraction,
            saccade,
            zoom,
            uncovered,
        };
        self.telemetry(&ring[pos], params, j, &r_view, shown)
    }

    /// The averaging window of output `j`: the ring positions `first..=pos`
    /// of its frames (`pos` the output's own), their orientations in
    /// `self.window_rots` and, with a rolling shutter, their readout rows in
    /// the warpers.
    fn window(
        &mut self,
        ring: &VecDeque<Buffered>,
        params: &StabilizerParams,
        j: u64,
    ) -> (usize, usize) {
        let pos = ring.iter().position(|b| b.index == j).unwrap_or(0);
        let window = match params.view.mode {
            Mode::None => 1,
            _ => params.render.n_avg,
        };
        let first = pos + 1 - window.min(pos + 1);
        self.window_rots.clear();
        self.window_rots
            .extend(ring.range(first..=pos).map(|b| b.r_est));
        if params.shutter.is_rolling() {
            // The window's readout rows, for the coverage test and the render.
            self.warper
                .set_readout_rows(ring.range(first..=pos).map(|b| &b.rows));
            self.chroma.set_readout_rows(self.warper.readout_rows());
        }
        (first, pos)
    }

    /// The telemetry of output `j`, the frame `cur` shown through `r_view`.
    fn telemetry(
        &mut self,
        cur: &Buffered,
        params: &StabilizerParams,
        j: u64,
        r_view: &Rot,
        shown: Shown,
    ) -> Telemetry {
        let (t, r_est, info) = (cur.t, cur.r_est, cur.info);
        let (rate_est, rate_view) = match self.last_shown {
            Some((tp, rp, vp)) if t > tp => (
                so3::body_rate(&rp, &r_est, t - tp),
                so3::body_rate(&vp, r_view, t - tp),
            ),
            _ => Default::default(),
        };
        self.last_shown = Some((t, r_est, *r_view));
        let zoomed = params.framing.zoom != Zoom::None;
        Telemetry {
            frame: j,
            t,
            r_est: so3::log(&r_est).into(),
            r_view: so3::log(r_view).into(),
            rate_est: rate_est.into(),
            rate_view: rate_view.into(),
            valid_fraction: shown.valid_fraction,
            frames_averaged: shown.frames_averaged,
            saccade: shown.saccade,
            zoom: if zoomed {
                shown.zoom
            } else {
                1.0 / (1.0 - 2.0 * params.render.margin)
            },
            uncovered: shown.uncovered,
            readout_rotation: (cur.intra.at(0.5) - cur.intra.at(-0.5)).into(),
            track: info,
        }
    }
}

/// What an output showed, for its telemetry.
struct Shown {
    frames_averaged: usize,
    valid_fraction: f64,
    saccade: bool,
    zoom: f64,
    uncovered: u64,
}
