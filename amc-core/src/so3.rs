//! The rotation group SO(3) and its Lie algebra so(3).
//!
//! Conventions (shared by the whole crate and by external checks):
//! * Camera frame: x right, y down, z forward.
//! * `R_{a,b}` maps a vector expressed in frame `b` into frame `a`, so
//!   `R_{0,j} = R_{0,k} R_{k,j}` and `R_{a,b}^T = R_{b,a}`.
//! * Body angular velocity of a camera between frames `j-1` and `j` is
//!   `w = log(R_{0,j-1}^T R_{0,j}) / dt` (expressed in camera `j-1`'s frame).
//!
//! Maps (Rodrigues), with `theta = |w|` and `[w]x` the skew matrix of `w`:
//! ```text
//! exp(w) = I + sin(theta)/theta [w]x + (1 - cos(theta))/theta^2 [w]x^2
//! log(R) = theta / (2 sin theta) (R - R^T)^v,   cos(theta) = (tr R - 1) / 2
//! ```
//! `exp` is nalgebra's `Rotation3::new`. `log` is ours: nalgebra's
//! `scaled_axis` takes `theta = acos((tr R - 1) / 2)`, which loses all precision
//! for small angles and returns NaN when rounding pushes the argument past 1
//! (it did, on near-identity view updates). Here
//! ```text
//! v = (R - R^T)^v = 2 sin(theta) a,   theta = atan2(|v| / 2, (tr R - 1) / 2)
//! log R = theta / (2 sin theta) v          (series 1/2 (1 + theta^2 / 6) v near 0)
//! ```
//! and near `theta = pi`, where `v` vanishes, the axis comes from the symmetric
//! part `R + R^T - 2 cos(theta) I = 2 (1 - cos theta) a a^T`.
//! Small-angle first order: `exp(w) x ~ x + w x x = x - [x]x w`, which gives the
//! warp Jacobian the tracker uses.

use nalgebra::{Matrix3, Rotation3, Vector3};

/// A rotation matrix in SO(3) (double precision for accumulation across a clip).
pub type Rot = Rotation3<f64>;
/// A tangent vector of so(3): axis times angle, in radians.
pub type Tangent = Vector3<f64>;

/// Exponential map so(3) -> SO(3).
#[inline]
pub fn exp(w: &Tangent) -> Rot {
    Rotation3::new(*w)
}

/// Angle (radians) below which `log` uses the series `theta / sin(theta) ~ 1 + theta^2 / 6`.
const LOG_SERIES_BELOW: f64 = 1e-4;
/// Distance from `pi` (radians) under which the axis is taken from the symmetric part.
const LOG_NEAR_PI: f64 = 1e-3;

/// Logarithm SO(3) -> so(3); the returned angle is in `[0, pi]`. Never NaN for
/// a finite rotation matrix.
pub fn log(r: &Rot) -> Tangent {
    let m = r.matrix();
    let v = Tangent::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    );
    let sin = 0.5 * v.norm();
    let cos = 0.5 * (m.trace() - 1.0);
    let theta = sin.atan2(cos);
    if theta < LOG_SERIES_BELOW {
        return v * (0.5 * (1.0 + theta * theta / 6.0));
    }
    if std::f64::consts::PI - theta > LOG_NEAR_PI {
        return v * (theta / (2.0 * sin));
    }
    // Near pi: a a^T = (R + R^T - 2 cos I) / (2 (1 - cos)); take the largest column.
    let sym =
        (m + m.transpose() - nalgebra::Matrix3::identity() * (2.0 * cos)) / (2.0 * (1.0 - cos));
    let k = (0..3)
        .max_by(|&i, &j| sym[(i, i)].total_cmp(&sym[(j, j)]))
        .unwrap_or(0);
    let mut axis = sym.column(k).into_owned();
    let n = axis.norm();
    if !(n > 0.0) {
        return Tangent::zeros();
    }
    axis /= n;
    // The sign of the axis follows v (which still carries 2 sin(theta) a).
    if axis.dot(&v) < 0.0 {
        axis = -axis;
    }
    axis * theta
}

/// Skew-symmetric ("hat") matrix with `hat(a) b = a x b`.
#[inline]
pub fn hat(w: &Tangent) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// Geodesic distance between two rotations, in radians.
#[inline]
pub fn angle_between(a: &Rot, b: &Rot) -> f64 {
    log(&(a.transpose() * b)).norm()
}

/// Re-orthonormalises a rotation that accumulated floating-point error.
#[inline]
///
/// The nearest rotation (the orthogonal polar factor), by Newton's iteration
/// `R <- (R + R^-T) / 2`, which converges quadratically from any matrix near
/// a rotation. (nalgebra's `from_matrix_eps` seeded with the matrix itself
/// returns it unchanged, which let the tracker's error compound from 1e-16
/// to 10% within a hundred frames of real footage.)
pub fn renormalize(r: &Rot) -> Rot {
    let mut m = *r.matrix();
    for _ in 0..RENORMALIZE_ITERATIONS {
        let Some(inv) = m.try_inverse() else {
            // Degenerate: fall back to Gram-Schmidt on the first two columns.
            return gram_schmidt(r.matrix());
        };
        let next = (m + inv.transpose()) * 0.5;
        let step = (next - m).norm();
        m = next;
        if step < 1e-15 {
            break;
        }
    }
    if !m.iter().all(|v| v.is_finite()) || m.determinant() <= 0.0 {
        return gram_schmidt(r.matrix());
    }
    Rotation3::from_matrix_unchecked(m)
}

/// Newton steps of [`renormalize`]: one takes an error of 1e-3 to 1e-6, two to
/// 1e-12, three to machine precision.
const RENORMALIZE_ITERATIONS: usize = 6;

/// Orthonormal frame from the first two columns of `m` (identity if degenerate).
fn gram_schmidt(m: &Matrix3<f64>) -> Rot {
    let x = m.column(0).into_owned();
    let y = m.column(1).into_owned();
    let (Some(x), Some(y)) = (
        x.try_normalize(1e-12),
        (y - x.normalize() * x.normalize().dot(&y)).try_normalize(1e-12),
    ) else {
        return Rot::identity();
    };
    let z = x.cross(&y);
    Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]))
}

/// Body angular velocity `log(R_prev^T R_cur) / dt`, in rad/s.
#[inline]
pub fn body_rate(prev: &Rot, cur: &Rot, dt: f64) -> Tangent {
    log(&(prev.transpose() * cur)) / dt
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    #[test]
    fn renormalize_restores_orthonormality() {
        let r = exp(&Tangent::new(0.3, -1.2, 2.0));
        // Scaled and skewed by 10%: what compounding had produced.
        let bad = Rot::from_matrix_unchecked(
            r.matrix() * Matrix3::new(1.1, 0.05, 0.0, 0.0, 0.95, 0.02, 0.01, 0.0, 1.05),
        );
        let fixed = renormalize(&bad);
        let m = fixed.matrix();
        assert_relative_eq!(m.transpose() * m, Matrix3::identity(), epsilon = 1e-13);
        assert_relative_eq!(m.determinant(), 1.0, epsilon = 1e-13);
        assert!(angle_between(&fixed, &r) < 0.1);
        // A rotation is left alone.
        assert_relative_eq!(*renormalize(&r).matrix(), *r.matrix(), epsilon = 1e-14);
        // Repeated composition with inverses stays orthonormal (what the tracker does).
        let mut acc = r;
        for k in 0..10_000 {
            let d = exp(&Tangent::new(1e-3 * k as f64, 0.2, -0.1));
            acc = renormalize(&(renormalize(&(acc.transpose() * d)).transpose() * d));
        }
        let m = acc.matrix();
        assert_relative_eq!(m.transpose() * m, Matrix3::identity(), epsilon = 1e-13);
    }

    #[test]
    fn identity_round_trip() {
        assert_relative_eq!(log(&exp(&Tangent::zeros())), Tangent::zeros());
    }

    #[test]
    fn log_is_accurate_for_tiny_angles_and_never_nan() {
        for &a in &[1e-12, 1e-9, 1e-7, 1e-5, 1e-3] {
            let w = Tangent::new(0.6, -0.8, 0.0) * a;
            let back = log(&exp(&w));
            assert!(back.iter().all(|x| x.is_finite()));
            assert!((back - w).norm() <= 1e-6 * a + 1e-15, "{a}: {back:?}");
        }
        // A matrix whose trace rounds above 3 (the case that broke acos).
        let mut m = nalgebra::Matrix3::identity();
        m[(0, 1)] = -1e-9;
        m[(1, 0)] = 1e-9;
        m[(0, 0)] = 1.0 + 1e-16;
        let r = Rot::from_matrix_unchecked(m);
        assert!(log(&r).iter().all(|x| x.is_finite()));
    }

    #[test]
    fn log_near_pi() {
        for &eps in &[0.0, 1e-9, 1e-6, 1e-4, 2e-3] {
            let axis = Tangent::new(1.0, 2.0, -2.0).normalize();
            let w = axis * (std::f64::consts::PI - eps);
            let back = log(&exp(&w));
            // At exactly pi, w and -w are the same rotation.
            let d = (back - w).norm().min((back + w).norm());
            assert!(d < 1e-6, "eps {eps}: {back:?} vs {w:?}");
        }
    }

    #[test]
    fn hat_is_cross_product() {
        let a = Tangent::new(0.3, -1.2, 2.0);
        let b = Tangent::new(-0.7, 0.1, 0.5);
        assert_relative_eq!(hat(&a) * b, a.cross(&b), epsilon = 1e-15);
    }

    #[test]
    fn small_angle_first_order() {
        let w = Tangent::new(1e-4, -2e-4, 3e-4);
        let x = Tangent::new(0.2, -0.1, 1.0);
        let first = x - hat(&x) * w;
        assert_relative_eq!(exp(&w) * x, first, epsilon = 1e-7);
    }

    proptest! {
        #[test]
        fn exp_log_round_trip(x in -2.0f64..2.0, y in -2.0f64..2.0, z in -2.0f64..2.0) {
            let w = Tangent::new(x, y, z);
            prop_assume!(w.norm() < 3.1);
            let back = log(&exp(&w));
            prop_assert!((back - w).norm() < 1e-9, "{w:?} -> {back:?}");
        }

        #[test]
        fn exp_is_orthonormal(x in -3.0f64..3.0, y in -3.0f64..3.0, z in -3.0f64..3.0) {
            let r = exp(&Tangent::new(x, y, z));
            let m = r.matrix();
            prop_assert!((m.transpose() * m - Matrix3::identity()).norm() < 1e-12);
            prop_assert!((m.determinant() - 1.0).abs() < 1e-12);
        }

        #[test]
        fn composition_and_inverse(a in -1.0f64..1.0, b in -1.0f64..1.0, c in -1.0f64..1.0) {
            let r = exp(&Tangent::new(a, b, c));
            prop_assert!(angle_between(&(r * r.transpose()), &Rot::identity()) < 1e-12);
            // R_{0,2} = R_{0,1} R_{1,2}: the body rate of the composition recovers R_{1,2}.
            let r12 = exp(&(Tangent::new(c, a, -b) * 0.1));
            let rate = body_rate(&r, &(r * r12), 0.5);
            prop_assert!((rate * 0.5 - log(&r12)).norm() < 1e-9);
        }
    }
}
