//! Fusion: each frame's orientation and readout path from the synchronized
//! gyro, held to the picture by the tracker.
//!
//! The gyro's frame-to-frame rotations are fine where vision's jitter (a
//! 1 kHz log integrates much of its noise away), but their chain drifts with
//! any bias left and breaks at a glitch; vision is drift-free against the
//! picture. So:
//! 1. each frame interval's rotation is the gyro's, except where it
//!    disagrees with the picture far beyond the clip's typical disagreement
//!    and the log's own signal breaks there (a spike, saturation, a dropout:
//!    the picture's step bridges it); a disagreement with no break near it
//!    is the picture's fault, and those frames' poses are left out;
//! 2. the chain of those steps is pulled onto vision's orientations by the
//!    exact smoother of a random walk (the chain's integrated noise, whose
//!    size the log's own noise gives) seen through vision's error (whose
//!    size the two's disagreement gives); frames where tracking was lost
//!    are weighted 0, so the gyro bridges them;
//! 3. each frame's rows get the gyro's own path through the readout.
//!
//! Offline: the smoother sees the whole clip (lookahead); see
//! `docs/gyro.md` for the measured accuracy.

use super::glitch::median;
use super::path::{vision_path, PathFit};
use super::samples::VisionPose;
use super::smooth::smooth_robust;
use super::track::GyroTrack;
use crate::error::AmcError;
use crate::shutter::IntraFrame;
use crate::so3::{self, Rot, Tangent};

/// When the gyro and the picture disagree.
#[derive(Clone, Debug, PartialEq)]
pub struct FuseParams {
    /// An interval disagreeing with the picture by more than this many times
    /// the clip's median disagreement (and more than `glitch_floor_rad_s`)
    /// is a gyro glitch where the log breaks near it, else vision's error.
    pub glitch_medians: f64,
    /// Disagreements under this are never glitches, rad/s.
    pub glitch_floor_rad_s: f64,
}

impl Default for FuseParams {
    fn default() -> Self {
        Self {
            glitch_medians: 6.0,
            glitch_floor_rad_s: 0.05,
        }
    }
}

impl FuseParams {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), AmcError> {
        if !(self.glitch_medians.is_finite() && self.glitch_medians >= 1.0) {
            return Err(AmcError::invalid(
                "glitch threshold",
                self.glitch_medians.to_string(),
                "at least 1 median",
            ));
        }
        if !(self.glitch_floor_rad_s.is_finite() && self.glitch_floor_rad_s >= 0.0) {
            return Err(AmcError::invalid(
                "glitch floor",
                self.glitch_floor_rad_s.to_string(),
                "0 rad/s or more",
            ));
        }
        Ok(())
    }
}

/// Where a fused frame's motion came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FusedFrom {
    /// The gyro, held to the picture.
    Gyro,
    /// The picture: the gyro glitched next to this frame, or its log does not cover it.
    Vision,
}

/// One fused frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusedPose {
    /// `R_{0,j}`, mid-readout.
    pub pose: Rot,
    /// Its motion during the readout (zero with a global shutter).
    pub path: IntraFrame,
    /// Where its steps came from.
    pub from: FusedFrom,
}

/// A clip's fused motion.
#[derive(Clone, Debug, PartialEq)]
pub struct Fusion {
    /// One per vision frame, in order.
    pub frames: Vec<FusedPose>,
    /// Frame intervals where the gyro glitched and vision bridged it.
    pub glitch_intervals: usize,
    /// Frames whose tracking was lost, or disagreed with the gyro where the
    /// log is sound, that the gyro bridged.
    pub bridged_frames: usize,
    /// The weight of vision against the gyro's chain (the smoother's
    /// `lambda`: vision's variance over the gyro's per frame interval).
    pub lambda: f64,
}

/// The smoother's reweightings.
const ROBUST_ROUNDS: usize = 3;
/// Bounds of the smoother's `lambda` (a noiseless gyro, a noiseless picture).
const LAMBDA_RANGE: (f64, f64) = (1e-6, 1e12);

/// Fuses `track` (a synchronized log) with vision's `frames`, whose rows are
/// read out over `readout_s` (0: a global shutter).
pub fn fuse(
    track: &GyroTrack,
    frames: &[VisionPose],
    readout_s: f64,
    params: &FuseParams,
) -> Result<Fusion, AmcError> {
    params.validate()?;
    let n = frames.len();
    if n == 0 {
        return Ok(Fusion {
            frames: Vec::new(),
            glitch_intervals: 0,
            bridged_frames: 0,
            lambda: 0.0,
        });
    }
    let intervals = n - 1;
    // 1. The steps, and where the gyro disagrees with the picture.
    let vision_step: Vec<Tangent> = frames
        .windows(2)
        .map(|f| so3::log(&(f[0].pose.transpose() * f[1].pose)))
        .collect();
    let gyro_step: Vec<Option<Tangent>> = frames
        .windows(2)
        .map(|f| track.between(f[0].t, f[1].t))
        .collect();
    let difference: Vec<Option<Tangent>> = (0..intervals)
        .map(|j| {
            let seen = !frames[j].lost && !frames[j + 1].lost;
            let dt = frames[j + 1].t - frames[j].t;
            (seen && dt > 0.0).then(|| gyro_step[j].map(|g| (g - vision_step[j]) / dt))?
        })
        .collect();
    let mut rates: Vec<f64> = difference.iter().flatten().map(|d| d.norm()).collect();
    let median_rate = median(&mut rates);
    let limit = (params.glitch_medians * median_rate).max(params.glitch_floor_rad_s);
    let over: Vec<bool> = difference
        .iter()
        .map(|d| d.is_some_and(|d| d.norm() > limit))
        .collect();
    let mut glitch = vec![false; intervals];
    let mut weight: Vec<f64> = frames
        .iter()
        .map(|f| if f.lost { 0.0 } else { 1.0 })
        .collect();
    let mut j = 0;
    while j < intervals {
        if !over[j] {
            j += 1;
            continue;
        }
        let start = j;
        while j < intervals && over[j] {
            j += 1;
        }
        // Intervals start..j, frames start..=j, with a frame interval's margin.
        let margin = frames[j].t - frames[j - 1].t;
        let (from, to) = (frames[start].t - margin, frames[j].t + margin);
        let breaks = track.breaks();
        let first = breaks.partition_point(|&b| b < from);
        if breaks.get(first).is_some_and(|&b| b <= to) {
            // The gyro's fault; its neighbours carry part of it.
            for g in &mut glitch[start.saturating_sub(1)..(j + 1).min(intervals)] {
                *g = true;
            }
        } else {
            for w in &mut weight[start..=j] {
                *w = 0.0;
            }
        }
    }
    let mut step: Vec<Tangent> = (0..intervals)
        .map(|j| match gyro_step[j] {
            Some(g) if !glitch[j] => g,
            _ => vision_step[j],
        })
        .collect();

    // 2. The chain, pulled onto vision; the bias the sync left (its fit
    // sees one interval at a time) is the chain's steady drift away from
    // the picture over the whole clip, removed first.
    let mut chain = chain_of(frames[0].pose, &step);
    for _ in 0..BIAS_ROUNDS {
        let drift = drift_rate(&chain, frames, &weight);
        for (j, s) in step.iter_mut().enumerate() {
            if gyro_step[j].is_some() && !glitch[j] {
                let dt = frames[j + 1].t - frames[j].t;
                // The world's drift rate in the frame's axes.
                *s += chain[j].transpose() * drift * dt;
            }
        }
        chain = chain_of(frames[0].pose, &step);
    }
    // Errors of the chain are the world's (left), not the frame's.
    let diff: Vec<[f64; 3]> = chain
        .iter()
        .zip(frames)
        .map(|(c, f)| {
            let d = so3::log(&(f.pose * c.transpose()));
            [d.x, d.y, d.z]
        })
        .collect();
    let lambda = weigh(track, frames, &difference, &over);
    let correction = smooth_robust(&diff, &weight, lambda, ROBUST_ROUNDS);

    // 3. Each frame's pose and path.
    let fit = PathFit::new();
    let out = (0..n)
        .map(|j| {
            let pose = so3::exp(&Tangent::from(correction[j])) * chain[j];
            let near_glitch = (j > 0 && glitch[j - 1]) || glitch.get(j).copied().unwrap_or(false);
            let covered = track.pose(frames[j].t).is_some();
            let from = if covered && !near_glitch {
                FusedFrom::Gyro
            } else {
                FusedFrom::Vision
            };
            let path = if readout_s <= 0.0 {
                IntraFrame::ZERO
            } else if from == FusedFrom::Gyro {
                fit.path(track, frames[j].t, readout_s)
                    .unwrap_or_else(|| vision_path(frames, j, readout_s))
            } else {
                vision_path(frames, j, readout_s)
            };
            FusedPose {
                pose: so3::renormalize(&pose),
                path,
                from,
            }
        })
        .collect();
    Ok(Fusion {
        frames: out,
        glitch_intervals: glitch.iter().filter(|g| **g).count(),
        bridged_frames: weight.iter().filter(|w| **w == 0.0).count(),
        lambda,
    })
}

/// Rounds of removing the bias left.
const BIAS_ROUNDS: usize = 2;

/// The chain of `steps` from `first`.
fn chain_of(first: Rot, steps: &[Tangent]) -> Vec<Rot> {
    let mut chain = Vec::with_capacity(steps.len() + 1);
    chain.push(first);
    for s in steps {
        let next = chain[chain.len() - 1] * so3::exp(s);
        chain.push(so3::renormalize(&next));
    }
    chain
}

/// The rate (rad/s, world axes) at which vision's orientations leave the
/// chain: the weighted least-squares slope of their difference over time.
fn drift_rate(chain: &[Rot], frames: &[VisionPose], weight: &[f64]) -> Tangent {
    let (mut sw, mut st, mut stt) = (0.0, 0.0, 0.0);
    let (mut sd, mut std) = (Tangent::zeros(), Tangent::zeros());
    for ((c, f), w) in chain.iter().zip(frames).zip(weight) {
        let d = so3::log(&(f.pose * c.transpose()));
        sw += w;
        st += w * f.t;
        stt += w * f.t * f.t;
        sd += d * *w;
        std += d * (w * f.t);
    }
    let den = sw * stt - st * st;
    if sw <= 0.0 || den.abs() < 1e-12 {
        return Tangent::zeros();
    }
    (std * sw - sd * st) / den
}

/// The smoother's `lambda`: vision's variance over the gyro's per frame
/// interval. The gyro's is its white noise integrated over an interval;
/// vision's follows from the disagreements' spread, which holds both
/// (each interval's difference has two poses' vision error and one
/// interval's gyro noise).
fn weigh(
    track: &GyroTrack,
    frames: &[VisionPose],
    difference: &[Option<Tangent>],
    over: &[bool],
) -> f64 {
    let span = frames[frames.len() - 1].t - frames[0].t;
    let dt = span / (frames.len() - 1).max(1) as f64;
    let rate = track.rate_hz().max(1.0);
    let gyro_var = track.noise_rad_s().powi(2) * dt / rate;
    // Robust spread per axis of the differences (rad/s), as radians per interval.
    let mut axes = [Vec::new(), Vec::new(), Vec::new()];
    for (d, _) in difference.iter().zip(over).filter(|(_, o)| !**o) {
        if let Some(d) = d {
            for (axis, v) in axes.iter_mut().zip(d.iter()) {
                axis.push((v * dt).abs());
            }
        }
    }
    if axes[0].is_empty() {
        return LAMBDA_RANGE.1;
    }
    let spread_var = axes
        .iter_mut()
        .map(|a| (1.4826 * median(a)).powi(2))
        .sum::<f64>()
        / 3.0;
    let vision_var = ((spread_var - gyro_var) / 2.0).max(0.01 * spread_var);
    (vision_var / gyro_var.max(f64::MIN_POSITIVE)).clamp(LAMBDA_RANGE.0, LAMBDA_RANGE.1)
}
