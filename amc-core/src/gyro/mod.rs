//! A camera's gyro log, synchronized from the video itself.
//!
//! The tracker's estimate is drift-free against the picture; a gyro log is
//! not synchronized with it (its clock starts seconds or minutes apart and
//! runs at its own rate), sits in the IMU's axes (an FPV camera is tilted
//! 20-40 deg on the flight controller) and carries a bias. All of that is
//! found here by matching the log against the video's own frame-to-frame
//! rotations, with nothing typed in:
//! - `integrate.rs`: the log's running integral, so that any interval's
//!   rotation is a difference of two interpolated values;
//! - `offset.rs`: the time offset, first over the log's whole span by the
//!   correlation of angular speeds (which no mounting changes), then to a
//!   fraction of a millisecond by the fit's residual; and the clock drift from
//!   the offsets of the clip's quarters;
//! - `mount.rs`: the mounting (Wahba's problem, solved by SVD) and the bias,
//!   robust to glitches (intervals where the gyro disagrees with the picture);
//! - `track.rs`: the synchronized log as camera orientations at any video time;
//! - `fuse.rs`: each frame's pose and readout path from the gyro, held to the
//!   picture (`smooth.rs`: the smoother that does it), glitches bridged by
//!   vision and lost frames by the gyro (`glitch.rs`: the log's own noise and
//!   breaks); `online.rs`: the same, causal, one frame at a time (a live
//!   feed, one pass over a long clip); `path.rs`: a frame's readout path;
//! - `readout.rs`: the rolling-shutter readout, the interval over which the
//!   log turns as each frame's rows did.
//!
//! Conventions: video time = log time + `offset_s`; `mount` takes IMU vectors
//! into the camera frame (x right, y down, z forward); the bias is in the
//! IMU's axes, rad/s.

mod fuse;
mod glitch;
mod integrate;
mod mount;
mod offset;
mod online;
mod path;
mod readout;
mod samples;
mod smooth;
mod track;

pub use fuse::{fuse, FuseParams, FusedFrom, FusedPose, Fusion};
pub use glitch::{breaks, noise_rad_s};
pub use integrate::GyroIntegral;
pub use mount::{fit_mount, MountFit};
pub use offset::{coarse_offset, refine_offset, speed_correlation};
pub use online::{OnlineFusion, OnlineParams};
pub use readout::{readout_from_gyro, MIN_READOUT_FRAMES};
pub use samples::{GyroSamples, GyroSync, VisionPose, VisionStep};
pub use smooth::{random_walk_smoother, smooth_robust};
pub use track::GyroTrack;

use thiserror::Error;

/// Why a log cannot be synchronized.
#[derive(Debug, Error, Clone, PartialEq)]
#[allow(missing_docs)] // Each variant's message says what its fields are.
pub enum GyroError {
    /// Too short a log.
    #[error("the gyro log has {samples} samples (at least {needed} are needed)")]
    TooFewSamples { samples: usize, needed: usize },
    /// Too short a clip.
    #[error("the video has {steps} frame intervals with motion (at least {needed} are needed)")]
    TooFewFrames { steps: usize, needed: usize },
    /// The log cannot cover the clip at any offset.
    #[error("the gyro log ({log_s:.1} s) cannot cover half of the video ({video_s:.1} s)")]
    LogTooShort { log_s: f64, video_s: f64 },
    /// No offset makes the log's motion the video's.
    #[error(
        "the gyro log does not match the video's motion (speed correlation {correlation:.2} at \
         best, below {needed}): another clip's log, or a camera that did not move"
    )]
    NoMatch { correlation: f64, needed: f64 },
    /// A sample that is not a number, or out of order.
    #[error("the gyro log has non-finite or unordered samples (at sample {index})")]
    BadSamples { index: usize },
}

/// Lowest speed correlation accepted as a match.
pub const MIN_CORRELATION: f64 = 0.5;
/// Correlation peaks within this of the best are told apart by the full fit.
const TIE: f64 = 0.05;
const MIN_SAMPLES: usize = 50;
const MIN_STEPS: usize = 20;

/// Checks a log and the video's steps (the steps kept: those finite and forward).
fn checked(gyro: &GyroSamples, steps: &[VisionStep]) -> Result<Vec<VisionStep>, GyroError> {
    if gyro.t.len() < MIN_SAMPLES || gyro.w.len() != gyro.t.len() {
        return Err(GyroError::TooFewSamples {
            samples: gyro.t.len().min(gyro.w.len()),
            needed: MIN_SAMPLES,
        });
    }
    if let Some(index) = (0..gyro.t.len()).find(|&i| {
        !gyro.t[i].is_finite()
            || gyro.w[i].iter().any(|v| !v.is_finite())
            || (i > 0 && gyro.t[i] <= gyro.t[i - 1])
    }) {
        return Err(GyroError::BadSamples { index });
    }
    let steps: Vec<VisionStep> = steps
        .iter()
        .copied()
        .filter(|s| s.rotation.iter().all(|v| v.is_finite()) && s.t1 > s.t0)
        .collect();
    if steps.len() < MIN_STEPS {
        return Err(GyroError::TooFewFrames {
            steps: steps.len(),
            needed: MIN_STEPS,
        });
    }
    Ok(steps)
}

/// [`sync`] of a log whose clock is the video's (`offset_s` known, no drift):
/// a camera's per-frame record such as GoPro's image orientation. The
/// mounting, the bias and the glitches are fitted; a log whose speeds do not
/// follow the video's at that offset is refused as [`sync`] refuses one.
pub fn sync_at(
    gyro: &GyroSamples,
    steps: &[VisionStep],
    offset_s: f64,
) -> Result<GyroSync, GyroError> {
    let steps = checked(gyro, steps)?;
    let integral = GyroIntegral::new(gyro);
    let correlation = speed_correlation(&integral, &steps, offset_s);
    if !(correlation >= MIN_CORRELATION) {
        return Err(GyroError::NoMatch {
            correlation,
            needed: MIN_CORRELATION,
        });
    }
    let fit = fit_mount(&integral, &steps, offset_s);
    Ok(GyroSync {
        offset_s,
        t_first: steps[0].t0,
        drift_ppm: 0.0,
        mount: fit.mount,
        bias: fit.bias,
        glitches: fit.glitches,
        residual_rad_s: fit.residual_rad_s,
        correlation,
    })
}

/// Synchronizes `gyro` with the video's `steps`: the offset over the log's
/// whole span, the clock drift, the mounting, the bias and the glitches.
pub fn sync(gyro: &GyroSamples, steps: &[VisionStep]) -> Result<GyroSync, GyroError> {
    let steps = checked(gyro, steps)?;
    let integral = GyroIntegral::new(gyro);
    let video_s = steps[steps.len() - 1].t1 - steps[0].t0;
    let log_s = integral.span().1 - integral.span().0;
    if log_s < offset::MIN_COVER * video_s {
        return Err(GyroError::LogTooShort { log_s, video_s });
    }
    let candidates = coarse_offset(&integral, &steps);
    let best_correlation = candidates.first().map_or(f64::NEG_INFINITY, |c| c.1);
    if best_correlation < MIN_CORRELATION {
        return Err(GyroError::NoMatch {
            correlation: best_correlation,
            needed: MIN_CORRELATION,
        });
    }
    // The peaks nearly as good as the best (speeds alone cannot tell a
    // motion from its mirror image) refined; the one the full fit (mounting
    // and bias) explains best wins.
    let (offset, fit, correlation) = candidates
        .iter()
        .filter(|c| c.1 >= MIN_CORRELATION && c.1 >= best_correlation - TIE)
        .map(|&(coarse, correlation)| {
            let offset = refine_offset(&integral, &steps, coarse, 0.03);
            (offset, fit_mount(&integral, &steps, offset), correlation)
        })
        .min_by(|a, b| a.1.residual_rad_s.total_cmp(&b.1.residual_rad_s))
        .expect("the best candidate passed");
    // The drift: the offsets of the clip's quarters against their times.
    let drift_ppm = offset::drift_ppm(&integral, &steps, offset);
    let t_first = steps[0].t0;
    let t_mid = 0.5 * (steps[0].t0 + steps[steps.len() - 1].t1);
    // `offset` fits the clip as a whole (its middle); stated at its start.
    let offset_s = offset - drift_ppm * 1e-6 * (t_mid - t_first);
    Ok(GyroSync {
        offset_s,
        t_first,
        drift_ppm,
        mount: fit.mount,
        bias: fit.bias,
        glitches: fit.glitches,
        residual_rad_s: fit.residual_rad_s,
        correlation,
    })
}

#[cfg(test)]
mod tests;
