//! The flapping-wing shake trajectory (see the crate's docs for the equations).

use crate::rng::SplitMix64;
use amc_core::error::{check_range, AmcError};
use amc_core::so3::{self, Rot, Tangent};
use nalgebra::{Matrix3, Vector3};
use std::f64::consts::PI;

/// Number of sinusoids per axis.
const COMPONENTS: usize = 8;

/// Length of the window over which the RMS angular speed is calibrated, s.
const CALIBRATION_SECONDS: f64 = 10.0;

/// Sampling rate of the calibration grid, Hz.
const CALIBRATION_RATE_HZ: f64 = 2000.0;

/// Parameters of the flapping-wing shake.
#[derive(Clone, Debug, PartialEq)]
pub struct ShakeParams {
    /// RMS angular speed of the shake, deg/s (`0..=2000`).
    pub shake_dps: f64,
    /// Frequency band of the shake, Hz: `0 < lo < hi <= 1000`.
    pub band_hz: (f64, f64),
    /// Seed of the generator: the same seed gives the same trajectory.
    pub seed: u64,
    /// Constant yaw pan rate, deg/s (positive turns the camera to the right),
    /// `-720..=720`.
    pub pan_dps: f64,
}

impl Default for ShakeParams {
    fn default() -> Self {
        Self {
            shake_dps: 100.0,
            band_hz: (12.0, 20.0),
            seed: 0,
            pan_dps: 0.0,
        }
    }
}

impl ShakeParams {
    /// Checks every parameter's range.
    pub fn validate(&self) -> Result<(), AmcError> {
        check_range(
            "shake angular speed (deg/s)",
            self.shake_dps,
            0.0,
            2000.0,
            "0 to 2000",
        )?;
        let (lo, hi) = self.band_hz;
        let band_ok = lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi && hi <= 1000.0;
        if !band_ok {
            return Err(AmcError::invalid(
                "shake band (Hz)",
                format!("{lo},{hi}"),
                "lo,hi with 0 < lo < hi <= 1000",
            ));
        }
        check_range(
            "pan rate (deg/s)",
            self.pan_dps,
            -720.0,
            720.0,
            "-720 to 720",
        )?;
        Ok(())
    }
}

/// One sinusoid of one axis: `amp * sin(omega t + phase)`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Component {
    amp: f64,
    omega: f64,
    phase: f64,
}

/// A deterministic shake trajectory (see the module header for the equations).
#[derive(Clone, Debug, PartialEq)]
pub struct Shake {
    params: ShakeParams,
    /// Per axis, the sinusoids with the final scale folded into `amp`.
    axes: [[Component; COMPONENTS]; 3],
    /// Pan rate, rad/s.
    pan: f64,
    /// `A(0)^T`.
    r0_inv: Rot,
}

/// Right Jacobian of SO(3): `exp(w + d) ~ exp(w) exp(J_r(w) d)`.
fn right_jacobian(w: &Tangent) -> Matrix3<f64> {
    let a2 = w.norm_squared();
    let a = a2.sqrt();
    let (c1, c2) = if a < 1e-4 {
        (0.5 - a2 / 24.0, 1.0 / 6.0 - a2 / 120.0)
    } else {
        ((1.0 - a.cos()) / a2, (a - a.sin()) / (a2 * a))
    };
    let k = so3::hat(w);
    Matrix3::identity() - k * c1 + k * k * c2
}

impl Shake {
    /// Builds the trajectory; fails when a parameter is out of range.
    pub fn new(params: &ShakeParams) -> Result<Self, AmcError> {
        params.validate()?;
        let (lo, hi) = params.band_hz;
        let mut rng = SplitMix64(params.seed);
        let mut axes = [[Component {
            amp: 0.0,
            omega: 0.0,
            phase: 0.0,
        }; COMPONENTS]; 3];
        let step = (hi - lo) / COMPONENTS as f64;
        for axis in axes.iter_mut() {
            for (k, c) in axis.iter_mut().enumerate() {
                let f = lo + step * (k as f64 + rng.next_f64());
                c.omega = 2.0 * PI * f;
                c.phase = 2.0 * PI * rng.next_f64();
                c.amp = 0.5 + 0.5 * rng.next_f64();
            }
        }
        let mut shake = Shake {
            params: params.clone(),
            axes,
            pan: params.pan_dps.to_radians(),
            r0_inv: Rot::identity(),
        };
        let target = params.shake_dps.to_radians();
        if target > 0.0 {
            // Small-angle estimate: E|theta'|^2 = sum_ik (a_ik w_ik)^2 / 2.
            let ms: f64 = shake
                .axes
                .iter()
                .flatten()
                .map(|c| (c.amp * c.omega).powi(2) / 2.0)
                .sum();
            shake.scale_amplitudes(target / ms.sqrt());
            for _ in 0..3 {
                let measured = shake.calibration_rms();
                if measured > 0.0 && measured.is_finite() {
                    shake.scale_amplitudes(target / measured);
                }
            }
        } else {
            shake.scale_amplitudes(0.0);
        }
        shake.r0_inv = shake.absolute(0.0).inverse();
        Ok(shake)
    }

    /// The parameters this trajectory was built from.
    pub fn params(&self) -> &ShakeParams {
        &self.params
    }

    fn scale_amplitudes(&mut self, s: f64) {
        for c in self.axes.iter_mut().flatten() {
            c.amp *= s;
        }
    }

    /// RMS of the shake part of the body rate on the calibration grid, rad/s.
    fn calibration_rms(&self) -> f64 {
        let n = (CALIBRATION_SECONDS * CALIBRATION_RATE_HZ) as usize;
        let mut sum = 0.0;
        for i in 0..n {
            let t = i as f64 / CALIBRATION_RATE_HZ;
            let (theta, dtheta) = self.theta_and_rate(t);
            sum += (right_jacobian(&theta) * dtheta).norm_squared();
        }
        (sum / n as f64).sqrt()
    }

    /// The shake angle vector `theta(t)` and its time derivative.
    fn theta_and_rate(&self, t: f64) -> (Tangent, Tangent) {
        let mut th = [0.0; 3];
        let mut dth = [0.0; 3];
        for (i, axis) in self.axes.iter().enumerate() {
            for c in axis {
                let (s, co) = (c.omega * t + c.phase).sin_cos();
                th[i] += c.amp * s;
                dth[i] += c.amp * c.omega * co;
            }
        }
        (Tangent::from(th), Tangent::from(dth))
    }

    /// The shake angle vector `theta(t)`, radians (without the pan).
    pub fn theta_at(&self, t: f64) -> Tangent {
        self.theta_and_rate(t).0
    }

    /// `A(t) = exp(p t e_y) exp(theta(t))`, not relative to the first frame.
    fn absolute(&self, t: f64) -> Rot {
        let pan = so3::exp(&Tangent::new(0.0, self.pan * t, 0.0));
        pan * so3::exp(&self.theta_at(t))
    }

    /// `R_{0}(t) = A(0)^T A(t)`: maps camera vectors at time `t` into the
    /// coordinates of the camera at `t = 0` (the world). Identity at `t = 0`.
    pub fn orientation_at(&self, t: f64) -> Rot {
        self.r0_inv * self.absolute(t)
    }

    /// Body angular velocity at `t` (rad/s, in the camera's own frame at `t`),
    /// pan included: `R(t)^T R(t + h) ~ exp(omega h)`.
    pub fn angular_velocity_at(&self, t: f64) -> Vector3<f64> {
        let (theta, dtheta) = self.theta_and_rate(t);
        let shake = right_jacobian(&theta) * dtheta;
        let pan = so3::exp(&theta).inverse() * Tangent::new(0.0, self.pan, 0.0);
        shake + pan
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn finite_difference_rms(shake: &Shake, rate_hz: f64, seconds: f64) -> (Vec<Tangent>, f64) {
        let h = 1.0 / rate_hz;
        let n = (seconds * rate_hz) as usize;
        let mut prev = shake.orientation_at(0.0);
        let mut rates = Vec::with_capacity(n);
        let mut sum = 0.0;
        for i in 1..=n {
            let cur = shake.orientation_at(i as f64 * h);
            let w = so3::body_rate(&prev, &cur, h);
            sum += w.norm_squared();
            rates.push(w);
            prev = cur;
        }
        (rates, (sum / n as f64).sqrt())
    }

    #[test]
    fn params_validation() {
        assert!(ShakeParams::default().validate().is_ok());
        let bad = [
            ShakeParams {
                shake_dps: -1.0,
                ..Default::default()
            },
            ShakeParams {
                shake_dps: 2000.5,
                ..Default::default()
            },
            ShakeParams {
                shake_dps: f64::NAN,
                ..Default::default()
            },
            ShakeParams {
                band_hz: (0.0, 20.0),
                ..Default::default()
            },
            ShakeParams {
                band_hz: (20.0, 12.0),
                ..Default::default()
            },
            ShakeParams {
                band_hz: (12.0, 1001.0),
                ..Default::default()
            },
            ShakeParams {
                pan_dps: f64::INFINITY,
                ..Default::default()
            },
        ];
        for p in bad {
            assert!(
                matches!(p.validate(), Err(AmcError::InvalidParameter { .. })),
                "{p:?}"
            );
            assert!(Shake::new(&p).is_err());
        }
    }

    #[test]
    fn rms_speed_matches_target() {
        for (dps, band, seed) in [
            (100.0, (12.0, 20.0), 0),
            (400.0, (5.0, 9.0), 7),
            (30.0, (40.0, 60.0), 3),
        ] {
            let shake = Shake::new(&ShakeParams {
                shake_dps: dps,
                band_hz: band,
                seed,
                pan_dps: 0.0,
            })
            .unwrap();
            let (_, rms) = finite_difference_rms(&shake, 1000.0, 10.0);
            let rel = (rms.to_degrees() - dps).abs() / dps;
            assert!(
                rel < 0.03,
                "dps {dps}: measured {} ({rel})",
                rms.to_degrees()
            );
        }
    }

    #[test]
    fn zero_shake_is_identity_and_pan_turns_right() {
        let shake = Shake::new(&ShakeParams {
            shake_dps: 0.0,
            pan_dps: 10.0,
            ..Default::default()
        })
        .unwrap();
        let r = shake.orientation_at(2.0);
        // Camera z (forward) turned toward +x by 20 degrees.
        let fwd = r * Vector3::z();
        assert!((fwd.x.atan2(fwd.z).to_degrees() - 20.0).abs() < 1e-9);
        let w = shake.angular_velocity_at(1.0);
        assert!((w - Vector3::new(0.0, 10f64.to_radians(), 0.0)).norm() < 1e-12);
    }

    #[test]
    fn spectrum_lies_in_band() {
        let (lo, hi) = (12.0, 20.0);
        let shake = Shake::new(&ShakeParams {
            band_hz: (lo, hi),
            seed: 11,
            ..Default::default()
        })
        .unwrap();
        let rate = 1000.0;
        let (rates, _) = finite_difference_rms(&shake, rate, 10.0);
        let win = (rate / lo).round() as usize;
        for axis in 0..3 {
            let x: Vec<f64> = rates.iter().map(|w| w[axis]).collect();
            let ms: f64 = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
            // Moving average over 1/lo seconds removes everything in the band.
            let mut lp = 0.0;
            let mut count = 0;
            let mut s: f64 = x[..win].iter().sum();
            for i in win..x.len() {
                lp += (s / win as f64).powi(2);
                count += 1;
                s += x[i] - x[i - win];
            }
            let ratio = (lp / count as f64 / ms).sqrt();
            assert!(ratio < 0.3, "axis {axis}: low-pass ratio {ratio}");
            // Hann-windowed DFT: nearly all power within [lo - 2, hi + 2] Hz.
            let n = x.len();
            let xw: Vec<f64> = x
                .iter()
                .enumerate()
                .map(|(i, v)| v * (0.5 - 0.5 * (2.0 * PI * i as f64 / n as f64).cos()))
                .collect();
            let total: f64 = xw.iter().map(|v| v * v).sum::<f64>() * n as f64;
            let df = rate / n as f64;
            let k0 = ((lo - 2.0) / df).floor() as usize;
            let k1 = ((hi + 2.0) / df).ceil() as usize;
            let mut band = 0.0;
            for k in k0..=k1 {
                let (mut re, mut im) = (0.0, 0.0);
                for (i, v) in xw.iter().enumerate() {
                    let (s, c) = (2.0 * PI * (k * i) as f64 / n as f64).sin_cos();
                    re += v * c;
                    im -= v * s;
                }
                band += 2.0 * (re * re + im * im);
            }
            let frac = band / total;
            assert!(frac > 0.97, "axis {axis}: in-band power fraction {frac}");
        }
    }

    #[test]
    fn deterministic_and_seed_dependent() {
        let p = ShakeParams {
            seed: 42,
            ..Default::default()
        };
        let a = Shake::new(&p).unwrap();
        let b = Shake::new(&p).unwrap();
        let c = Shake::new(&ShakeParams {
            seed: 43,
            ..p.clone()
        })
        .unwrap();
        for t in [0.1, 1.234, 9.9] {
            assert_eq!(a.orientation_at(t), b.orientation_at(t));
            assert!(so3::angle_between(&a.orientation_at(t), &c.orientation_at(t)) > 1e-6);
        }
    }

    #[test]
    fn first_orientation_is_identity() {
        let shake = Shake::new(&ShakeParams {
            pan_dps: 5.0,
            seed: 9,
            ..Default::default()
        })
        .unwrap();
        assert!(so3::angle_between(&shake.orientation_at(0.0), &Rot::identity()) < 1e-14);
        // Amplitudes are small: a few degrees at most.
        let max = (0..1000)
            .map(|i| shake.theta_at(i as f64 * 0.01).norm().to_degrees())
            .fold(0.0, f64::max);
        assert!(max > 0.1 && max < 10.0, "max shake angle {max} deg");
    }

    #[test]
    fn angular_velocity_matches_finite_differences() {
        let shake = Shake::new(&ShakeParams {
            shake_dps: 800.0,
            pan_dps: 30.0,
            seed: 5,
            ..Default::default()
        })
        .unwrap();
        let h = 1e-6;
        for t in [0.0, 0.37, 2.5, 7.77] {
            let fd = so3::body_rate(
                &shake.orientation_at(t - h),
                &shake.orientation_at(t + h),
                2.0 * h,
            );
            let w = shake.angular_velocity_at(t);
            assert!(
                (fd - w).norm() < 1e-5 * w.norm().max(1.0),
                "t {t}: {fd:?} vs {w:?}"
            );
        }
    }
}
