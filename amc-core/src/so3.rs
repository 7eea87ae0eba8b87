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
//! Both are delegated to nalgebra's `Rotation3::new` / `scaled_axis`, which use
//! Taylor expansions near `theta = 0` and handle `theta` near `pi` robustly.
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

/// Logarithm SO(3) -> so(3); the returned angle is in `[0, pi]`.
#[inline]
pub fn log(r: &Rot) -> Tangent {
    r.scaled_axis()
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
pub fn renormalize(r: &Rot) -> Rot {
    Rotation3::from_matrix_eps(r.matrix(), 1e-12, 20, *r)
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
    fn identity_round_trip() {
        assert_relative_eq!(log(&exp(&Tangent::zeros())), Tangent::zeros());
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
