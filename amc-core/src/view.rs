//! The stable viewpoint: a low-pass filter on SO(3), or a fixed view that
//! "saccades".
//!
//! ## Filter (paper, "Computation of a Stable View")
//! ```text
//! w      = log(R_view^T R_hat_{0,j})          geodesic from the view to the estimate
//! alpha  = clamp((a + b |w|) dt, 0, 1)         a = 2 /s, b = 20 /(rad s) (paper: 40)
//! R_view <- R_view exp(alpha w)
//! ```
//! `dt` is the real interval between the frames' timestamps, so a 30 fps clip is
//! smoothed with the same time constants as a 60 fps one. `a` sets the cut-off
//! for small deviations (~0.3 Hz); `b |w|` lets the view catch up quickly when
//! the camera turns away on purpose. Our default `b` is half the paper's: the
//! framing (`crate::framing`) now keeps the view within the crop budget by
//! pulling it toward the camera where needed, so the filter itself may smooth
//! more (see `docs/core-history.md#view-rate-b`).
//!
//! ## Lookahead (offline, zero phase)
//! With `N` future frames, the forward-filtered views `F_j..F_{j+N}` are filtered
//! once more backwards in time, `B_{j+N} = F_{j+N}`,
//! `B_i = B_{i+1} exp(alpha_i log(B_{i+1}^T F_i))`, and frame `j` is shown from `B_j`.
//! As in `filtfilt`, the backward pass cancels the forward pass's phase lag.
//!
//! ## Roll
//! In stabilize mode the view's roll (its turn about the optical axis) is, by
//! [`Roll`]: smoothed with pan and tilt (the paper's view); locked level with
//! the first frame, keeping the filtered optical axis `z_v` and choosing the
//! right axis `x = normalize(e_y x z_v)` (no component along the first
//! frame's down axis `e_y`), `y = z_v x x`; or the camera's own, the shown view
//! being the camera turned by the shortest rotation taking its optical axis onto
//! `z_v` (so only pan and tilt are smoothed).
//!
//! Roll may have gains of its own (`roll_rate_a`, `roll_rate_b`): the step
//! `alpha w` is then taken per axis of the view's frame, `alpha` on pan and
//! tilt (`w_x`, `w_y`) and `alpha_roll` on roll (`w_z`).
//!
//! ## Lock
//! Every axis held at the first frame's orientation (a tripod, vid.stab's
//! `tripod=1`); with `zoom` auto or static the framing pulls it toward the
//! camera just as far as the crop budget needs, so it never shows a border.
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
    /// Every axis locked at the first frame's orientation (a tripod); with a
    /// zoom, pulled toward the camera only as far as the crop budget needs.
    Lock,
    /// The view is the camera itself: undistorted, cropped, averaged, not stabilized.
    None,
}

impl std::str::FromStr for Mode {
    type Err = AmcError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "stabilize" => Ok(Mode::Stabilize),
            "saccade" => Ok(Mode::Saccade),
            "lock" => Ok(Mode::Lock),
            "none" => Ok(Mode::None),
            _ => Err(AmcError::invalid(
                "mode",
                s,
                "stabilize, saccade, lock or none",
            )),
        }
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Mode::Stabilize => "stabilize",
            Mode::Saccade => "saccade",
            Mode::Lock => "lock",
            Mode::None => "none",
        })
    }
}

/// How the view's roll moves in stabilize mode (see the module's "Roll").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Roll {
    /// Smoothed with pan and tilt by the same filter (the paper's view).
    #[default]
    Smooth,
    /// Held level with the first frame: the horizon keeps the first frame's
    /// angle whatever the camera does ("horizon lock"); pan and tilt are smoothed.
    Lock,
    /// The camera's own roll: only pan and tilt are smoothed, the horizon turns
    /// with the craft (as FPV pilots fly).
    Follow,
}

impl std::str::FromStr for Roll {
    type Err = AmcError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "smooth" => Ok(Roll::Smooth),
            "lock" => Ok(Roll::Lock),
            "follow" => Ok(Roll::Follow),
            _ => Err(AmcError::invalid("roll", s, "smooth, lock or follow")),
        }
    }
}

impl Roll {
    /// The view shown for the filtered `view` of a frame whose camera is
    /// `camera` (both `R_{0,j}`): `view` with its roll set as this mode says.
    /// Where the construction has no answer (the optical axis along the first
    /// frame's down axis for `Lock`, opposite to the camera's for `Follow`),
    /// `view` is kept.
    pub fn apply(self, view: &Rot, camera: &Rot) -> Rot {
        let z = view.matrix().column(2).into_owned();
        match self {
            Roll::Smooth => *view,
            Roll::Lock => {
                let x = nalgebra::Vector3::y().cross(&z);
                let norm = x.norm();
                if norm < 1e-6 {
                    return *view;
                }
                let x = x / norm;
                let y = z.cross(&x);
                so3::renormalize(&Rot::from_matrix_unchecked(
                    nalgebra::Matrix3::from_columns(&[x, y, z]),
                ))
            }
            Roll::Follow => {
                let zc = camera.matrix().column(2).into_owned();
                match Rot::rotation_between(&zc, &z) {
                    Some(swing) => so3::renormalize(&(swing * camera)),
                    None => *view,
                }
            }
        }
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
    /// Gain growing with the deviation, per second per radian (`b / dt`; default
    /// 20, paper: 40, see the module's docs). Range 0..=10000.
    pub rate_b: f64,
    /// Saccade when fewer than this share of output pixels is covered by every
    /// averaged frame (paper: 0.9). Range 0..=1.
    pub saccade_coverage: f64,
    /// Future frames used to smooth the view (0 = online, as in the paper).
    /// Adds this many frames of latency. Range 0..=600.
    pub lookahead: usize,
    /// The view's roll in stabilize mode: smoothed, locked level with the
    /// first frame, or the camera's (default smoothed).
    pub roll: Roll,
    /// Roll's own constant filter gain, per second (default: `rate_a`, the
    /// same as pan and tilt). Range 0..=1000.
    pub roll_rate_a: Option<f64>,
    /// Roll's own deviation-growing gain, per second per radian (default:
    /// `rate_b`). Range 0..=10000.
    pub roll_rate_b: Option<f64>,
}

impl Default for ViewParams {
    fn default() -> Self {
        Self {
            mode: Mode::Stabilize,
            rate_a: 2.0,
            rate_b: 20.0,
            saccade_coverage: 0.9,
            lookahead: 0,
            roll: Roll::Smooth,
            roll_rate_a: None,
            roll_rate_b: None,
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
        if let Some(a) = self.roll_rate_a {
            check_range("roll_rate_a", a, 0.0, 1000.0, "0..=1000 per second")?;
        }
        if let Some(b) = self.roll_rate_b {
            check_range(
                "roll_rate_b",
                b,
                0.0,
                10000.0,
                "0..=10000 per second per radian",
            )?;
        }
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

    /// One filter step: moves `view` toward `target`. With roll gains of its
    /// own, the geodesic `w` (in the view's frame, `z` its optical axis) is
    /// scaled per axis: `(alpha w_x, alpha w_y, alpha_roll w_z)`.
    pub fn step(&self, view: &Rot, target: &Rot, dt: f64) -> Rot {
        let w = so3::log(&(view.transpose() * target));
        let alpha = self.alpha(w.norm(), dt);
        let step = if self.roll_rate_a.is_none() && self.roll_rate_b.is_none() {
            w * alpha
        } else {
            let a = self.roll_rate_a.unwrap_or(self.rate_a);
            let b = self.roll_rate_b.unwrap_or(self.rate_b);
            let alpha_roll = ((a + b * w.norm()) * dt).clamp(0.0, 1.0);
            so3::Tangent::new(alpha * w.x, alpha * w.y, alpha_roll * w.z)
        };
        so3::renormalize(&(view * so3::exp(&step)))
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

    fn roll_deg(r: &Rot) -> f64 {
        // How far the right axis leans out of the first frame's level plane.
        r.matrix()[(1, 0)].asin().to_degrees()
    }

    #[test]
    fn roll_modes_keep_the_optical_axis_and_set_the_roll() {
        let view = so3::exp(&Tangent::new(0.2, -0.3, 0.25));
        let camera = so3::exp(&Tangent::new(0.25, -0.2, -0.4));
        assert_eq!(Roll::Smooth.apply(&view, &camera), view);
        for mode in [Roll::Lock, Roll::Follow] {
            let shown = mode.apply(&view, &camera);
            let (a, b) = (shown.matrix().column(2), view.matrix().column(2));
            assert!((a - b).norm() < 1e-12, "{mode:?} moved the optical axis");
            assert!((shown.matrix().determinant() - 1.0).abs() < 1e-12);
        }
        assert!(roll_deg(&view).abs() > 5.0);
        assert!(roll_deg(&Roll::Lock.apply(&view, &camera)).abs() < 1e-9);
        // Follow: the camera turned without twist about its own optical axis.
        let rel = so3::log(&(camera.transpose() * Roll::Follow.apply(&view, &camera)));
        assert!(rel.z.abs() < 1e-12, "{rel:?}");
        // Degenerate: looking straight along the first frame's down axis.
        let down = so3::exp(&Tangent::new(std::f64::consts::FRAC_PI_2, 0.0, 0.0));
        assert_eq!(Roll::Lock.apply(&down, &camera), down);
        assert_eq!("LOCK".parse::<Roll>().unwrap(), Roll::Lock);
        assert!("level".parse::<Roll>().is_err());
    }

    #[test]
    fn roll_gains_of_its_own_smooth_roll_apart() {
        // A pure roll step and a pure pan step: with roll's gain at 0 the view
        // never rolls but still pans; without roll gains, both as before.
        let mut p = ViewParams::default();
        let roll = so3::exp(&Tangent::new(0.0, 0.0, 0.2));
        let pan = so3::exp(&Tangent::new(0.0, 0.2, 0.0));
        let same = p.step(&Rot::identity(), &roll, 1.0 / 30.0);
        p.roll_rate_a = Some(0.0);
        p.roll_rate_b = Some(0.0);
        assert_eq!(p.step(&Rot::identity(), &roll, 1.0 / 30.0), Rot::identity());
        let panned = p.step(&Rot::identity(), &pan, 1.0 / 30.0);
        assert!(so3::angle_between(&panned, &Rot::identity()) > 0.01);
        assert!(so3::angle_between(&same, &Rot::identity()) > 0.01);
        p.roll_rate_a = Some(-1.0);
        assert!(p.validate().is_err());
        assert_eq!("lock".parse::<Mode>().unwrap(), Mode::Lock);
    }

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
        // (2 + 20 * 0.1) / 30
        assert!((p.alpha(0.1, 1.0 / 30.0) - 4.0 / 30.0).abs() < 1e-12);
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
