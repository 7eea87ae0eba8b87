//! The track loop: a tracker's construction, and each frame from its warm
//! start to its template reset.
//!
//! Robustness:
//! * Warm start: the best (lowest coarse-level loss) of the previous estimate,
//!   a constant angular-velocity prediction, and the template pose itself.
//!   Flapping-wing shake at 12-20 Hz sampled at 60 fps reverses within 2-3
//!   frames, so a constant-velocity guess alone can be worse than none.

use super::intrinsics::Intrinsics;
use super::pace::{PACE_GAIN, START_PATH_GAIN};
use super::params::{TrackInfo, TrackerParams};
use super::recover::suspect;
use super::state::Gauge;
use super::state::Handover;
use super::state::LevelTemplate;
use super::state::Pose;
use super::state::WarmStart;
use super::Tracker;
use crate::camera::CameraModel;
use crate::error::AmcError;
use crate::pyramid::Pyramid;
use crate::shutter::{IntraFrame, RowTime};
use crate::so3::{self, Rot, Tangent};

/// Longest a template reset may be postponed while frames track badly.
pub(super) const MAX_RESET_DELAY: usize = 10;

impl Tracker {
    /// A tracker for frames of `camera` (a pinhole: undistort first).
    pub fn new(camera: &CameraModel, params: TrackerParams) -> Result<Self, AmcError> {
        params.validate()?;
        if !camera.is_pinhole() {
            return Err(AmcError::invalid(
                "tracking camera",
                "a distorted model",
                "a pinhole (the tracker runs on undistorted images)",
            ));
        }
        let n_levels = Pyramid::level_count(camera.width, camera.height, params.pyramid_levels);
        Ok(Self {
            start_path_free: false,
            base: Intrinsics::from_camera(camera),
            width: camera.width,
            height: camera.height,
            n_levels,
            template: vec![LevelTemplate::default(); n_levels],
            outgoing: vec![LevelTemplate::default(); n_levels],
            handover: None,
            handover_warm: WarmStart::default(),
            r_0k: Rot::identity(),
            r_kj: Rot::identity(),
            last: None,
            rate: Tangent::zeros(),
            frames_since_reset: 0,
            score: Vec::new(),
            static_votes: vec![0.0; camera.width * camera.height],
            typical_residual: None,
            intra: IntraFrame::ZERO,
            rolling: None,
            row_tables: Vec::new(),
            readout_s: 0.0,
            gauge_tpl: IntraFrame::ZERO,
            gauge: Gauge::default(),
            prior_mean: IntraFrame::ZERO,
            pace: (0.0, 0.0),
            frame_dt: 0.0,
            tpl_path: IntraFrame::ZERO,
            gauge_settled: false,
            gauge_corrections: IntraFrame::ZERO,
            warm_start: WarmStart::default(),
            params,
        })
    }

    /// Pyramid levels the caller must build for [`Tracker::track`].
    pub fn levels(&self) -> usize {
        self.n_levels
    }

    /// Size of the finest pyramid level the tracker expects.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Parameters in use.
    pub fn params(&self) -> &TrackerParams {
        &self.params
    }

    /// Turns the rolling-shutter model on: `rows` gives the readout fraction
    /// of each pixel of the tracked images. Each frame's motion during its
    /// readout is then estimated with its rotation ([`Tracker::intra`]).
    /// Set it before the first frame.
    pub fn set_rolling(&mut self, rows: RowTime, readout_s: f64) {
        // Each level's size as the pyramid halves it (see `pyramid::half_into`).
        let (mut w, mut h) = (self.width, self.height);
        self.row_tables.clear();
        for level in 0..self.n_levels {
            match rows.level_table(level, w, h) {
                Some(table) => self.row_tables.push(table),
                None => break,
            }
            (w, h) = (w / 2, h / 2);
        }
        self.rolling = Some(rows);
        self.readout_s = readout_s;
    }

    /// The last tracked frame's motion during its readout (zero with a
    /// global shutter).
    pub fn intra(&self) -> IntraFrame {
        self.intra
    }

    /// Tracks the next frame (its pyramid and timestamp in seconds) and returns
    /// `R_{0,j}`, the rotation from this camera to the first frame's camera.
    pub fn track(&mut self, pyr: &Pyramid, t: f64) -> (Rot, TrackInfo) {
        let Some((t_prev, r_prev)) = self.last else {
            // First frame: it is the reference orientation and the first template.
            self.set_template(pyr);
            self.r_0k = Rot::identity();
            self.r_kj = Rot::identity();
            self.last = Some((t, Rot::identity()));
            let info = TrackInfo {
                template_reset: true,
                valid_fraction: 1.0,
                ..Default::default()
            };
            return (Rot::identity(), info);
        };
        let dt = t - t_prev;
        if dt.is_finite() && dt > 0.0 {
            self.frame_dt = dt;
        }

        // Warm-start candidates, as rotations relative to the template.
        // At most three candidates; a fixed array keeps `track` allocation-free.
        // With a rolling shutter each starts from the last frame's readout motion.
        // Terms that are not estimated (all but `phi` at a slow pace) are zero.
        let intra = self
            .intra
            .truncated(self.path_terms())
            .plus(&self.gauge_tpl, 1.0);
        self.prior_mean = self.path_of_rate(&self.rate).plus(&self.gauge_tpl, 1.0);
        let pose = |r| Pose { r, intra };
        let mut candidates = [
            pose(self.r_kj),
            pose(Rot::identity()),
            pose(Rot::identity()),
        ];
        let mut n_cand = 1;
        if self.params.predict && dt.is_finite() && dt > 0.0 {
            let predicted = r_prev * so3::exp(&(self.rate * dt));
            candidates[n_cand] = pose(self.r_0k.transpose() * predicted);
            n_cand += 1;
        }
        candidates[n_cand] = pose(Rot::identity());
        n_cand += 1;
        let coarsest = self.n_levels - 1;
        let mut start = candidates[0];
        let mut best = f64::INFINITY;
        for c in &candidates[..n_cand] {
            let e = self
                .evaluate(coarsest, &pyr.levels[coarsest], c, None)
                .mean_loss();
            if e < best {
                best = e;
                start = *c;
            }
        }

        let mut warm_start = std::mem::take(&mut self.warm_start);
        let (mut pose, mut info) = self.coarse_to_fine(pyr, start, dt, &mut warm_start);
        if self.rolling.is_some() && self.pace.1 == 0.0 {
            // The pace is not known yet (the first two frame pairs): the
            // whole path too, kept where the slow model leaves far more.
            self.start_path_free = true;
            let (free, free_info) = self.coarse_to_fine(pyr, start, dt, &mut warm_start);
            self.start_path_free = false;
            let spent = info.iterations + free_info.iterations;
            if free_info.rms_residual < START_PATH_GAIN * info.rms_residual {
                (pose, info) = (free, free_info);
            }
            info.iterations = spent;
        }
        if suspect(&info, self.typical_residual) {
            let (p2, info2) = self.recover(pyr, pose, dt, &mut warm_start);
            if info2.rms_residual < info.rms_residual {
                pose = p2;
                info = TrackInfo {
                    iterations: info.iterations + info2.iterations,
                    ..info2
                };
            }
        }
        self.warm_start = warm_start;
        let good = !suspect(&info, self.typical_residual) && !info.lost;
        if let Some(handover) = self.handover.take() {
            if good {
                info.iterations += self.hand_over(pyr, &pose, dt, handover);
            }
        }
        if good {
            let t = self.typical_residual.get_or_insert(info.rms_residual);
            *t += 0.1 * (info.rms_residual - *t);
        }
        self.r_kj = so3::renormalize(&pose.r);
        self.intra = pose.intra.plus(&self.gauge_tpl, -1.0);
        if self.params.reject_static && !info.lost {
            let r_kj = self.r_kj;
            self.vote_static(&pyr.levels[0], &r_kj);
        }
        let r_0j = so3::renormalize(&(self.r_0k * self.r_kj));
        if dt.is_finite() && dt > 0.0 {
            let rate = so3::body_rate(&r_prev, &r_0j, dt);
            if self.rolling.is_some() && good {
                let (c, p) = (rate.dot(&self.rate), rate.norm_squared());
                if self.rate == Tangent::zeros() {
                    // No earlier rate yet (the second frame).
                } else if self.pace.1 == 0.0 {
                    self.pace = (c, p);
                } else {
                    self.pace.0 += PACE_GAIN * (c - self.pace.0);
                    self.pace.1 += PACE_GAIN * (p - self.pace.1);
                }
            }
            self.rate = rate;
            if self.rolling.is_some() && good && self.check_gauge() {
                self.settle_gauge();
            }
        }
        self.last = Some((t, r_0j));

        self.frames_since_reset += 1;
        // With a rolling shutter the first template is held until the gauge
        // is first known (see [`Tracker::settle_gauge`]).
        let due = self.frames_since_reset >= self.params.n_track
            && (self.gauge_settled || !self.fast_motion());
        let overdue = self.frames_since_reset >= self.params.n_track + MAX_RESET_DELAY;
        if (due && good) || overdue {
            // The outgoing template stays for the next frame's handover; its
            // buffers are the ones the next reset after that fills.
            std::mem::swap(&mut self.template, &mut self.outgoing);
            self.handover = Some(Handover {
                r_0k: self.r_0k,
                gauge_tpl: self.gauge_tpl,
            });
            self.set_template(pyr);
            self.r_0k = r_0j;
            self.r_kj = Rot::identity();
            info.template_reset = true;
        }
        (r_0j, info)
    }
}
