//! A frame's motion during its readout: the gyro's own path through the
//! rows (a fourth-order fit of its rotation at the readout's samples), or,
//! where the gyro cannot give it, vision's angular velocity times the readout.

use super::samples::VisionPose;
use super::track::GyroTrack;
use crate::shutter::{IntraFrame, INTRA_TERMS};
use crate::so3::{self, Tangent};
use nalgebra::{Matrix4, Vector4};

/// Readout samples the path is fitted to.
const PATH_SAMPLES: usize = 17;

/// A frame's readout path from vision alone: its angular velocity (the
/// central difference of its neighbours' poses) times the readout.
pub(super) fn vision_path(frames: &[VisionPose], j: usize, readout_s: f64) -> IntraFrame {
    let (a, b) = (j.saturating_sub(1), (j + 1).min(frames.len() - 1));
    rate_path(&frames[a], &frames[j], &frames[b], readout_s)
}

/// Frame `j`'s readout path from the rate between frames `a` and `b`
/// (`a == j` or `b == j` for a one-sided difference, as online fusion needs).
pub(super) fn rate_path(
    a: &VisionPose,
    j: &VisionPose,
    b: &VisionPose,
    readout_s: f64,
) -> IntraFrame {
    let dt = b.t - a.t;
    if dt <= 0.0 {
        return IntraFrame::ZERO;
    }
    // The rate in frame j's axes.
    let w = j.pose.transpose() * a.pose * so3::log(&(a.pose.transpose() * b.pose)) / dt;
    IntraFrame {
        phi: w * readout_s,
        ..IntraFrame::ZERO
    }
}

/// The least-squares fit of `a(s) = s phi + s^2 psi + s^3 chi + s^4 xi` to
/// the gyro's rotation at readout fractions `s` in `[-1/2, 1/2]`.
#[derive(Clone, Debug)]
pub(super) struct PathFit {
    s: [f64; PATH_SAMPLES],
    /// `(A^T A)^-1 A^T`, one row per term.
    solve: [[f64; PATH_SAMPLES]; INTRA_TERMS],
}

impl PathFit {
    pub(super) fn new() -> Self {
        let s: [f64; PATH_SAMPLES] =
            std::array::from_fn(|k| -0.5 + k as f64 / (PATH_SAMPLES - 1) as f64);
        let mut ata = Matrix4::zeros();
        for &sk in &s {
            let row = Vector4::new(sk, sk * sk, sk.powi(3), sk.powi(4));
            ata += row * row.transpose();
        }
        let inv = ata
            .try_inverse()
            .expect("the readout samples span four powers");
        let mut solve = [[0.0; PATH_SAMPLES]; INTRA_TERMS];
        for (k, &sk) in s.iter().enumerate() {
            let col = inv * Vector4::new(sk, sk * sk, sk.powi(3), sk.powi(4));
            for (term, row) in solve.iter_mut().enumerate() {
                row[k] = col[term];
            }
        }
        Self { s, solve }
    }

    /// Frame `t`'s path over a readout of `readout_s`, `None` where the log
    /// does not cover it.
    pub(super) fn path(&self, track: &GyroTrack, t: f64, readout_s: f64) -> Option<IntraFrame> {
        let mid = track.pose(t)?;
        let mut a = [Tangent::zeros(); PATH_SAMPLES];
        for (ak, &sk) in a.iter_mut().zip(&self.s) {
            *ak = so3::log(&(mid.transpose() * track.pose(t + sk * readout_s)?));
        }
        let terms: [Tangent; INTRA_TERMS] = std::array::from_fn(|term| {
            a.iter().zip(&self.solve[term]).map(|(ak, c)| ak * *c).sum()
        });
        Some(IntraFrame::from_terms(terms))
    }
}
