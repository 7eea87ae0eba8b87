//! The tracking stage: frames in, orientations (and readout paths) out.

use crate::frontend::TrackingFrontend;
use crate::image::FrameRef;
use crate::pyramid::Pyramid;
use crate::shutter::{GaugeEase, IntraFrame, TrajectorySmoother};
use crate::so3::Rot;
use crate::tracker::{TrackInfo, Tracker};

/// The tracking stage: frames in, orientations out.
pub(super) struct Tracking {
    pub(super) frontend: TrackingFrontend,
    pub(super) tracker: Tracker,
    pub(super) pyr: Pyramid,
    /// With a rolling shutter, the recent frames' poses and readout paths
    /// fitted as one trajectory, which gives each frame its pose (`None`: a
    /// global shutter, or switched off with
    /// [`Stabilizer::set_trajectory_smoothing`](super::Stabilizer::set_trajectory_smoothing)).
    pub(super) smoother: Option<TrajectorySmoother>,
    /// With a rolling shutter, the gauge's corrections eased into the
    /// rendered paths.
    pub(super) ease: GaugeEase,
}

/// One frame as [`Tracking`] estimated it.
pub(super) struct Tracked {
    /// `R_{0,j}`, at mid-readout.
    pub(super) pose: Rot,
    /// Its motion during the readout, as best known (telemetry).
    pub(super) path: IntraFrame,
    /// The motion its rows are rendered with: `path` with the gauge's latest
    /// corrections eased in ([`GaugeEase`]).
    pub(super) rendered: IntraFrame,
    pub(super) info: TrackInfo,
}

impl Tracking {
    /// Estimates the orientation of `frame`, taken at `t`.
    pub(super) fn track(&mut self, frame: &FrameRef<'_>, t: f64) -> Tracked {
        let levels = self.tracker.levels();
        self.frontend.prepare(frame, &mut self.pyr, levels);
        let gauge_before = self.tracker.gauge_corrections();
        let (r, info) = self.tracker.track(&self.pyr, t);
        let mut pose = r;
        let mut path = self.tracker.intra();
        let mut corrections = self.tracker.gauge_corrections();
        if let Some(smoother) = &mut self.smoother {
            // The frames held were reported before this frame's correction
            // of the gauge, if it made one: they move with it, so that the
            // window keeps one common offset.
            smoother.regauge(&corrections.plus(&gauge_before, -1.0));
            let weight = if info.lost { 0.0 } else { 1.0 };
            let smoothed = smoother.push(t, r, path, weight);
            // At a slow pace the tracker fits `phi` alone, which leaves the
            // pose as certain as a global shutter's: there the fit only adds
            // its own assumptions (see
            // `docs/core-history.md#stabilizer-slow-pace-pose`), and the
            // tracker's own pose and gauge stand.
            if self.tracker.estimates_bend() {
                // A new template is rectified again with its path's level as
                // the trajectory finds it (the tracker's own gauge check is
                // slower and noisier); frames aligned to it inherit it.
                if let (true, Some(error)) = (info.template_reset, smoother.path_offset()) {
                    self.tracker.regauge_template(&error);
                    // This frame, pushed before, and the ones held move alike.
                    smoother.regauge(&self.tracker.gauge_corrections().plus(&corrections, -1.0));
                }
                pose = smoothed;
                path = self.tracker.intra();
                corrections = self.tracker.gauge_corrections();
                // Until the tracker first checks its gauge (8 frames), every
                // path is off by minus the first frame's: the trajectory's
                // offset finds it from the third frame on.
                if let (false, Some(offset)) =
                    (self.tracker.gauge_known(), smoother.fitted_offset())
                {
                    path = path.plus(&offset, -1.0);
                    corrections = corrections.plus(&offset, 1.0);
                }
            }
        }
        let rendered = self.ease.rendered(&path, &corrections);
        Tracked {
            pose,
            path,
            rendered,
            info,
        }
    }
}
