//! The rolling-shutter readout from a synchronized log (`readout_ms = auto`
//! where the camera records none).
//!
//! Tracked with the rolling-shutter model on, each frame's rotation during
//! its readout, `phi_j`, is measured from the intensities (a free parameter
//! per frame, whatever readout the tracker was given; see
//! [`crate::readout`]). The gyro says how far the camera turned over any
//! interval. The readout is the interval, centred on each frame's
//! mid-readout time, over which the gyro turns as the picture did:
//! ```text
//! tau* = argmin_tau  sum_j | phi_j - log(R(t_j - tau/2)^T R(t_j + tau/2)) |^2
//! ```
//! Video alone must interpolate the path between frames, which a 12-20 Hz
//! shake at 60 frames/s barely samples; the gyro has it at its own rate.
//! Frames whose measurement disagrees with the gyro by far more than the
//! rest (a glitch, a lost frame, a moving object) are left out of a second
//! fit. Judged as [`crate::readout`]'s estimate is (the same [`ReadoutEstimate`]).

use super::track::GyroTrack;
use crate::readout::{refine_minimum, Fit, MeasuredReadout, ReadoutEstimate};
use crate::so3::Tangent;

/// Readouts tried on the grid before the golden section (over two frame
/// periods, as [`crate::readout`] searches: a synthetic clip may read out
/// for longer than a frame lasts).
const GRID_STEPS: usize = 400;
/// Frames whose residual is more than this many times the median are left
/// out of the second fit.
const OUTLIER_FACTOR: f64 = 4.0;
/// Least frames a fit needs.
pub const MIN_READOUT_FRAMES: usize = 20;
/// Most frames a fit uses (evenly spread over a longer clip).
pub const MAX_READOUT_FRAMES: usize = 600;

/// The readout of `frames` (in time order, lost ones left out: as
/// [`crate::readout::measured`] gives them)
/// against `track`, searched over `0..=2 frame_period_s`; `None` with fewer
/// than [`MIN_READOUT_FRAMES`] frames the log covers. At most
/// [`MAX_READOUT_FRAMES`] frames are used.
pub fn readout_from_gyro(
    track: &GyroTrack,
    frames: &[MeasuredReadout],
    frame_period_s: f64,
) -> Option<ReadoutEstimate> {
    if !(frame_period_s > 0.0 && frame_period_s.is_finite()) {
        return None;
    }
    let half = frame_period_s;
    let step = half / GRID_STEPS as f64;
    // Each frame with the gyro's rotation over its centred intervals.
    let every = frames.len().div_ceil(MAX_READOUT_FRAMES).max(1);
    let covered: Vec<Covered> = frames
        .iter()
        .step_by(every)
        .filter(|f| f.phi.iter().all(|v| v.is_finite()))
        .filter_map(|f| {
            let turns = (0..=GRID_STEPS)
                .map(|i| track.between(f.t - step * i as f64, f.t + step * i as f64))
                .collect::<Option<Vec<_>>>()?;
            Some(Covered { frame: *f, turns })
        })
        .collect();
    if covered.len() < MIN_READOUT_FRAMES {
        return None;
    }
    let first = best_on_grid(&covered);
    // A second fit without the frames far off the first.
    let residuals: Vec<f64> = covered.iter().map(|c| c.residual(first)).collect();
    let mut sorted = residuals.clone();
    sorted.sort_by(f64::total_cmp);
    let limit = OUTLIER_FACTOR * OUTLIER_FACTOR * sorted[sorted.len() / 2];
    let kept: Vec<Covered> = covered
        .into_iter()
        .zip(&residuals)
        .filter_map(|(c, &r)| (r <= limit).then_some(c))
        .collect();
    let i = best_on_grid(&kept);
    // Between grid points: the golden section on the exact intervals.
    let sse = |h: f64| -> f64 {
        kept.iter()
            .map(|c| match track.between(c.frame.t - h, c.frame.t + h) {
                Some(g) => (c.frame.phi - g).norm_squared(),
                None => c.residual(i),
            })
            .sum()
    };
    let (h, best) = refine_minimum(sse, step * i as f64, step, 0.0, half);
    let total: f64 = kept.iter().map(|c| c.frame.phi.norm_squared()).sum();
    // The gyro's rotation over a quarter frame period (turns[GRID_STEPS / 8]
    // spans an eighth of one on each side).
    let quarter = GRID_STEPS / 8;
    let motion_deg = (kept
        .iter()
        .map(|c| c.turns[quarter].norm_squared())
        .sum::<f64>()
        / kept.len() as f64)
        .sqrt()
        .to_degrees();
    let fit = Fit {
        sse: best,
        total,
        samples: kept.len(),
    };
    Some(ReadoutEstimate::judged(
        2.0 * h * 1000.0,
        fit,
        motion_deg,
        kept.len(),
    ))
}
/// A frame and the gyro's rotation over each interval of the grid.
struct Covered {
    frame: MeasuredReadout,
    turns: Vec<Tangent>,
}

impl Covered {
    fn residual(&self, i: usize) -> f64 {
        (self.frame.phi - self.turns[i]).norm_squared()
    }
}

/// The grid index with the least sum of squared residuals.
fn best_on_grid(covered: &[Covered]) -> usize {
    (0..=GRID_STEPS)
        .map(|i| (i, covered.iter().map(|c| c.residual(i)).sum::<f64>()))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("the grid has points")
        .0
}
