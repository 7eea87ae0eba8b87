//! The mounting and the bias at a given offset: the rotation `M` and bias
//! `b` minimizing `sum_j |d_j - M (g_j - b dt_j)|^2` over the frame intervals
//! (`d_j` the video's rotation, `g_j` the gyro's over the same interval).
//! For fixed `b` it is Wahba's problem, solved by the SVD of
//! `B = sum d_j (g_j - b dt_j)^T` (`M = U diag(1, 1, det(U V^T)) V^T`); for
//! fixed `M` the bias is linear least squares. A few alternations converge.
//! Intervals whose disagreement is far above the others' (a spike, a
//! saturated axis, a dropout) are left out and counted as glitches.

use super::integrate::GyroIntegral;
use super::samples::VisionStep;
use crate::so3::Rot;
use nalgebra::{Matrix3, Vector3};

/// The fit at one offset.
#[derive(Clone, Debug)]
pub struct MountFit {
    /// The rotation taking IMU vectors into the camera frame.
    pub mount: Rot,
    /// The gyro's bias, rad/s, IMU axes.
    pub bias: Vector3<f64>,
    /// Intervals left out as glitches.
    pub glitches: usize,
    /// RMS disagreement of the intervals kept, rad/s.
    pub residual_rad_s: f64,
    /// Sum of squared disagreements (rad^2) of the intervals kept.
    pub cost: f64,
    /// Intervals the log covers.
    pub covered: usize,
}

/// Alternations of mounting and bias, and rounds of leaving out glitches.
const ROUNDS: usize = 4;
/// An interval disagreeing by more than this many times the median (and more
/// than [`GLITCH_FLOOR`]) is a glitch.
const GLITCH_MEDIANS: f64 = 6.0;
/// Disagreements under this are never glitches, rad/s (about 6 deg/s).
const GLITCH_FLOOR: f64 = 0.1;

/// Fits mounting and bias with video time = log time + `offset`.
pub fn fit_mount(integral: &GyroIntegral, steps: &[VisionStep], offset: f64) -> MountFit {
    let pairs: Vec<(Vector3<f64>, Vector3<f64>, f64)> = steps
        .iter()
        .filter_map(|s| {
            let g = integral.between(s.t0 - offset, s.t1 - offset)?;
            Some((s.rotation, g, s.t1 - s.t0))
        })
        .collect();
    let mut keep = vec![true; pairs.len()];
    let (mut mount, mut bias) = (Rot::identity(), Vector3::zeros());
    let mut errors = vec![0.0; pairs.len()];
    for round in 0..ROUNDS {
        for _ in 0..3 {
            mount = wahba(&pairs, &keep, &bias);
            bias = bias_given(&pairs, &keep, &mount);
        }
        for (e, (d, g, dt)) in errors.iter_mut().zip(&pairs) {
            *e = (d - mount * (g - bias * *dt)).norm() / dt;
        }
        if round + 1 < ROUNDS {
            let mut sorted: Vec<f64> = errors.clone();
            sorted.sort_by(f64::total_cmp);
            let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
            let limit = (GLITCH_MEDIANS * median).max(GLITCH_FLOOR);
            for (k, e) in keep.iter_mut().zip(&errors) {
                *k = *e <= limit;
            }
        }
    }
    let kept: Vec<usize> = (0..pairs.len()).filter(|&i| keep[i]).collect();
    let cost: f64 = kept.iter().map(|&i| (errors[i] * pairs[i].2).powi(2)).sum();
    let residual_rad_s = if kept.is_empty() {
        f64::INFINITY
    } else {
        (kept.iter().map(|&i| errors[i].powi(2)).sum::<f64>() / kept.len() as f64).sqrt()
    };
    MountFit {
        mount,
        bias,
        glitches: pairs.len() - kept.len(),
        residual_rad_s,
        cost,
        covered: pairs.len(),
    }
}

/// The rotation `M` minimizing `sum |d - M (g - b dt)|^2` over the kept pairs.
fn wahba(pairs: &[(Vector3<f64>, Vector3<f64>, f64)], keep: &[bool], bias: &Vector3<f64>) -> Rot {
    let mut b = Matrix3::zeros();
    for ((d, g, dt), _) in pairs.iter().zip(keep).filter(|(_, k)| **k) {
        b += d * (g - bias * *dt).transpose();
    }
    let svd = b.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Rot::identity();
    };
    let sign = (u * v_t).determinant().signum();
    let m = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, sign)) * v_t;
    Rot::from_matrix_unchecked(m)
}

/// The bias `b` minimizing `sum |d - M (g - b dt)|^2` for a fixed `M`:
/// `M^T d = g - b dt`, so `b = sum dt (g - M^T d) / sum dt^2`.
fn bias_given(
    pairs: &[(Vector3<f64>, Vector3<f64>, f64)],
    keep: &[bool],
    mount: &Rot,
) -> Vector3<f64> {
    let (mut num, mut den) = (Vector3::zeros(), 0.0);
    for ((d, g, dt), _) in pairs.iter().zip(keep).filter(|(_, k)| **k) {
        num += (g - mount.transpose() * d) * *dt;
        den += dt * dt;
    }
    if den > 0.0 {
        num / den
    } else {
        Vector3::zeros()
    }
}
