//! The stable viewpoint: a low-pass filter on SO(3), or a fixed view that
//! "saccades".
//!
//! ## Filter (paper, "Computation of a Stable View")
//! ```text
//! w      = log(R_view^T R_hat_{0,j})          geodesic from the view to the estimate
//! alpha  = clamp((a + b |w|) dt, 0, 1)         a = 2 /s, b = 40 /(rad s)
//! R_view <- R_view exp(alpha w)
//! ```
//! `dt` is the real interval between the frames' timestamps, so a 30 fps clip is
//! smoothed with the same time constants as a 60 fps one. `a` sets the cut-off
//! for small deviations (~0.3 Hz); `b |w|` lets the view catch up quickly when
//! the camera turns away on purpose.
//!
//! ## Lookahead (offline, zero phase)
//! With `N` future frames, the forward-filtered views `F_j..F_{j+N}` are filtered
//! once more backwards in time, `B_{j+N} = F_{j+N}`,
//! `B_i = B_{i+1} exp(alpha_i log(B_{i+1}^T F_i))`, and frame `j` is shown from `B_j`.
//! As in `filtfilt`, the backward pass cancels the forward pass's phase lag.
//!
//! ## Saccade
//! The view is held fixed; the stabilizer re-centres it on the current estimate
//! when fewer than `saccade_coverage` of the output pixels are covered by every
//! averaged frame.

use crate::error::{check_range, AmcError};
use crate::so3::{self, Rot};
use serde::{Deserialize, Serialize};

/// Largest `lookahead`, frames. The stabilizer keeps `lookahead` decoded frames
/// in memory (about 6 MB each at 1080p RGB), so this bounds its memory.
pub const MAX_LOOKAHEAD: usize = 600;

/// How the viewpoint moves.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Low-pass filtered view that follows the camera smoothly (the paper's main mode).
    #[default]
    Stabilize,
    /// Fixed view, re-centred when coverage drops (the least apparent motion).
    Saccade,
    /// The view is the camera itself: undistorted, cropped, averaged, not stabilized.
    None,
}

impl std::str::FromStr for Mode {
    type Err = AmcError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "stabilize" => Ok(Mode::Stabilize),
            "saccade" => Ok(Mode::Saccade),
            "none" => Ok(Mode::None),
            _ => Err(AmcError::invalid("mode", s, "stabilize, saccade or none")),
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Mode::Stabilize => "stabilize",
            Mode::Saccade => "saccade",
            Mode::None => "none",
        })
    }
}

/// Parameters of the viewpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ViewParams {
    /// How the view moves.
    pub mode: Mode,
    /// Constant part of the filter gain, per second (`a / dt`; paper: 2). Range 0..=1000.
    pub rate_a: f64,
    /// Gain growing with the deviation, per second per radian (`b / dt`; paper: 40). Range 0..=10000.
    pub rate_b: f64,
    /// Saccade when fewer than this share of output pixels is covered by every
    /// averaged frame (paper: 0.9). Range 0..=1.
    pub saccade_coverage: f64,
    /// Future frames used to smooth the view (0 = online, as in the paper).
    /// Adds this many frames of latency. Range 0..=600.
    pub lookahead: usize,
}

impl Default for ViewParams {
    fn default() -> Self {
        Self {
            mode: Mode::Stabilize,
            rate_a: 2.0,
            rate_b: 40.0,
            saccade_coverage: 0.9,
            lookahead: 0,
        }
    }
}

impl ViewParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<(), AmcError> {
        check_range("rate_a", self.rate_a, 0.0, 1000.0, "0..=1000 per second")?;
        check_range(
            "rate_b",
            self.rate_b,
            0.0,
            10000.0,
            "0..=10000 per second per radian",
        )?;
        check_range("saccade_coverage", self.saccade_coverage, 0.0, 1.0, "0..=1")?;
        if self.lookahead > MAX_LOOKAHEAD {
            return Err(AmcError::invalid(
                "lookahead",
                self.lookahead,
                "0..=600 frames",
            ));
        }
        Ok(())
    }

    /// The filter gain `alpha = clamp((a + b |w|) dt, 0, 1)`.
    pub fn alpha(&self, w_norm: f64, dt: f64) -> f64 {
        ((self.rate_a + self.rate_b * w_norm) * dt).clamp(0.0, 1.0)
    }

    /// One filter step: moves `view` toward `target`.
    pub fn step(&self, view: &Rot, target: &Rot, dt: f64) -> Rot {
        let w = so3::log(&(view.transpose() * target));
        let alpha = self.alpha(w.norm(), dt);
        so3::renormalize(&(view * so3::exp(&(w * alpha))))
    }
}

/// The zero-phase backward pass over forward-filtered views `(t, F_i)`, oldest
/// first; returns the view for the oldest entry.
pub fn backward_pass(params: &ViewParams, window: &[(f64, Rot)]) -> Rot {
    let Some(&(mut t_next, mut b)) = window.last() else {
        return Rot::identity();
    };
    for &(t, f) in window.iter().rev().skip(1) {
        b = params.step(&b, &f, t_next - t);
        t_next = t;
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::so3::Tangent;

    #[test]
    fn filter_converges_to_a_constant_target() {
        let p = ViewParams::default();
        let target = so3::exp(&Tangent::new(0.0, 0.3, 0.0));
        let mut v = Rot::identity();
        for _ in 0..600 {
            v = p.step(&v, &target, 1.0 / 60.0);
        }
        assert!(so3::angle_between(&v, &target) < 1e-3);
    }

    #[test]
    fn alpha_is_clamped_and_uses_dt() {
        let p = ViewParams::default();
        assert!((p.alpha(0.0, 1.0 / 60.0) - 2.0 / 60.0).abs() < 1e-12);
        assert!((p.alpha(0.1, 1.0 / 30.0) - 6.0 / 30.0).abs() < 1e-12);
        assert_eq!(p.alpha(100.0, 1.0), 1.0);
        assert_eq!(p.alpha(0.0, -1.0), 0.0);
    }

    #[test]
    fn filter_attenuates_shake() {
        // 15 Hz, 2 degree oscillation about x: the view should move far less.
        let p = ViewParams::default();
        let mut v = Rot::identity();
        let mut max_dev: f64 = 0.0;
        for j in 0..600 {
            let t = j as f64 / 60.0;
            let target = so3::exp(&Tangent::new(
                (2f64).to_radians() * (30.0 * std::f64::consts::PI * t).sin(),
                0.0,
                0.0,
            ));
            v = p.step(&v, &target, 1.0 / 60.0);
            if j > 60 {
                max_dev = max_dev.max(so3::log(&v).norm());
            }
        }
        assert!(
            max_dev < 0.5f64.to_radians(),
            "view moved {} deg",
            max_dev.to_degrees()
        );
    }

    #[test]
    fn backward_pass_removes_lag() {
        // A steady pan: the forward filter lags; forward+backward should not.
        let p = ViewParams::default();
        let rate = 0.5; // rad/s yaw
        let dt = 1.0 / 60.0;
        let mut v = Rot::identity();
        let mut fwd = Vec::new();
        for j in 0..400 {
            let target = so3::exp(&Tangent::new(0.0, rate * j as f64 * dt, 0.0));
            v = p.step(&v, &target, dt);
            fwd.push((j as f64 * dt, v));
        }
        let j = 300;
        let truth = so3::exp(&Tangent::new(0.0, rate * j as f64 * dt, 0.0));
        let lag_fwd = so3::angle_between(&fwd[j].1, &truth);
        let zero_phase = backward_pass(&p, &fwd[j..j + 60]);
        let lag_zp = so3::angle_between(&zero_phase, &truth);
        assert!(
            lag_zp < 0.5 * lag_fwd,
            "forward {lag_fwd}, zero-phase {lag_zp}"
        );
    }
}
