//! Corrections of the readout paths' gauge, eased into the rendered frames.
//!
//! The tracker sees a frame's readout path only relative to its template's
//! (see [`crate::tracker`]'s gauge): the first frame's own path is unknown
//! and taken as zero, so until the gauge is first found every path is off
//! by minus the first frame's, and later checks correct it again by small
//! amounts. Each correction moves every later path at once; rendered as it
//! comes, the picture's shear jumps in one frame, and the first correction
//! is the whole rotation across a readout (see `docs/core-history.md#shutter-ease`).
//!
//! So the rendered path is the best estimate plus the part of the
//! corrections not yet shown, `T - S`: `T` the corrections made so far, and
//! `S` following `T` by a share `1 / EASE_FRAMES` per frame. A correction
//! `c` then reaches the picture as steps of `c / N, c (1 - 1/N) / N, ...`:
//! the flow it adds falls from `|c|^2` to about `|c|^2 / (2 N)`, and the
//! first frames' shear fades out within about `2 N` frames (0.3 s at 60
//! frames/s) instead of snapping. Telemetry keeps the estimate itself.

use super::IntraFrame;

/// Frames over which a correction of the gauge reaches the rendered paths (the
/// time constant of its exponential approach): long enough to hide the jump,
/// short enough that the first frames' shear does not linger (see
/// `docs/core-history.md#shutter-ease-frames`).
pub const EASE_FRAMES: f64 = 12.0;

/// The corrections shown so far (see the module's doc).
#[derive(Clone, Copy, Debug)]
pub struct GaugeEase {
    shown: IntraFrame,
}

impl Default for GaugeEase {
    fn default() -> Self {
        Self {
            shown: IntraFrame::ZERO,
        }
    }
}

impl GaugeEase {
    /// The path to render for the next frame: `path` its estimate (in the
    /// gauge as known now) and `corrections` the sum of the corrections of
    /// the gauge behind that estimate (what the paths have moved by, minus,
    /// since the first frame's gauge; see
    /// [`crate::tracker::Tracker::gauge_corrections`]).
    pub fn rendered(&mut self, path: &IntraFrame, corrections: &IntraFrame) -> IntraFrame {
        let pending = corrections.plus(&self.shown, -1.0);
        self.shown = self.shown.plus(&pending, 1.0 / EASE_FRAMES);
        path.plus(&corrections.plus(&self.shown, -1.0), 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::so3::Tangent;

    fn phi(x: f64) -> IntraFrame {
        IntraFrame {
            phi: Tangent::new(x, -0.5 * x, 0.25 * x),
            ..IntraFrame::ZERO
        }
    }

    /// Without corrections the estimate is rendered as it is, bit for bit.
    #[test]
    fn no_correction_renders_the_estimate() {
        let mut ease = GaugeEase::default();
        for j in 0..50 {
            let path = phi(0.01 * (j as f64).sin());
            assert_eq!(ease.rendered(&path, &IntraFrame::ZERO), path);
        }
    }

    /// A correction `c` made at one frame moves the estimates by `-c`: the
    /// rendered path moves by at most `|c| / N` per frame, and reaches the
    /// estimate (to 1% of `c`) within `5 N` frames.
    #[test]
    fn a_correction_is_eased_in() {
        let mut ease = GaugeEase::default();
        let truth = phi(0.02);
        let c = phi(0.03);
        // Before the correction the estimate is off by `c`; after it, exact.
        let mut last = ease.rendered(&truth.plus(&c, 1.0), &IntraFrame::ZERO);
        assert_eq!(last, truth.plus(&c, 1.0));
        let c_norm = c.phi.norm();
        for j in 0..(5.0 * EASE_FRAMES) as usize {
            let shown = ease.rendered(&truth, &c);
            let step = (shown.phi - last.phi).norm();
            assert!(
                step <= c_norm / EASE_FRAMES + 1e-12,
                "frame {j}: step {step}"
            );
            last = shown;
        }
        assert!((last.phi - truth.phi).norm() < 0.01 * c_norm, "{last:?}");
        // Corrections add up: a second one `d` moves the estimate by `-d`,
        // and is eased in from where the first one left the rendered path.
        let d = phi(-0.01);
        let shown = ease.rendered(&truth.plus(&d, -1.0), &c.plus(&d, 1.0));
        let bound = 0.01 * c_norm + phi(-0.01).phi.norm() / EASE_FRAMES + 1e-12;
        assert!((shown.phi - last.phi).norm() <= bound);
    }
}
