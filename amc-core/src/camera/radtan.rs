//! Radial-tangential distortion (`Distortion::RadTan`, OpenCV `projectPoints` with 5
//! coefficients), with `x = X/Z, y = Y/Z, r^2 = x^2 + y^2`:
//! ```text
//! radial = 1 + k1 r^2 + k2 r^4 + k3 r^6
//! xd = x * radial + 2 p1 x y + p2 (r^2 + 2 x^2)
//! yd = y * radial + p1 (r^2 + 2 y^2) + 2 p2 x y
//! ```
//! Valid for `Z > eps * |ray|` and `r < r_max`, where `r_max` is the first radius at which
//! the radial map `r (1 + k1 r^2 + k2 r^4 + k3 r^6)` stops increasing, i.e. the first
//! positive root of `1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3` in `s = r^2` (infinite if none).
//! Beyond it the polynomial folds back and the model is meaningless.
//!
//! The inverse uses a damped 2-D Newton iteration (falling back to a bracketed 1-D radial
//! solve for the starting point under strong distortion) and rejects pixels beyond `r_max`
//! and solutions that fail to converge.

use super::pinhole::perspective;
use super::poly::{first_positive_root, invert_odd_poly, monotone_on, MAX_NEWTON};

/// Radial-tangential coefficients, unpacked.
pub(super) struct RadTan {
    pub(super) k1: f64,
    pub(super) k2: f64,
    pub(super) p1: f64,
    pub(super) p2: f64,
    pub(super) k3: f64,
}

/// Ray -> distorted normalized coordinates, or `None` outside the valid domain.
#[inline]
pub(super) fn distort(c: &RadTan, x: f64, y: f64, z: f64) -> Option<(f64, f64)> {
    let (a, b) = perspective(x, y, z)?;
    let s = a * a + b * b;
    if !monotone_on(&deriv_coeffs_radtan(c.k1, c.k2, c.k3), s) {
        return None;
    }
    Some(radtan_apply(c, a, b))
}

/// Applies radial-tangential distortion to undistorted normalized `(x, y)`.
#[inline]
fn radtan_apply(c: &RadTan, x: f64, y: f64) -> (f64, f64) {
    let s = x * x + y * y;
    let radial = 1.0 + s * (c.k1 + s * (c.k2 + s * c.k3));
    let xy = x * y;
    (
        x * radial + 2.0 * c.p1 * xy + c.p2 * (s + 2.0 * x * x),
        y * radial + c.p1 * (s + 2.0 * y * y) + 2.0 * c.p2 * xy,
    )
}

/// Radial-tangential distortion and its Jacobian `[[dX/dx, dX/dy], [dY/dx, dY/dy]]`.
#[inline]
fn radtan_with_jacobian(c: &RadTan, x: f64, y: f64) -> ((f64, f64), [[f64; 2]; 2]) {
    let s = x * x + y * y;
    let radial = 1.0 + s * (c.k1 + s * (c.k2 + s * c.k3));
    let dradial = c.k1 + s * (2.0 * c.k2 + s * 3.0 * c.k3); // d radial / d s
    let xy = x * y;
    let f = (
        x * radial + 2.0 * c.p1 * xy + c.p2 * (s + 2.0 * x * x),
        y * radial + c.p1 * (s + 2.0 * y * y) + 2.0 * c.p2 * xy,
    );
    let cross = 2.0 * xy * dradial + 2.0 * c.p1 * x + 2.0 * c.p2 * y;
    let j = [
        [
            radial + 2.0 * x * x * dradial + 2.0 * c.p1 * y + 6.0 * c.p2 * x,
            cross,
        ],
        [
            cross,
            radial + 2.0 * y * y * dradial + 6.0 * c.p1 * y + 2.0 * c.p2 * x,
        ],
    ];
    (f, j)
}

/// Inverts radial-tangential distortion: distorted `(xd, yd)` -> undistorted `(x, y)`.
pub(super) fn undistort_radtan(c: &RadTan, xd: f64, yd: f64) -> Option<(f64, f64)> {
    let dcoef = deriv_coeffs_radtan(c.k1, c.k2, c.k3);
    // Fast path: Newton from the distorted point itself (converges for realistic lenses).
    if let Some((x, y)) = newton_radtan(c, xd, yd, xd, yd) {
        if monotone_on(&dcoef, x * x + y * y) {
            return Some((x, y));
        }
    }
    // Robust path: solve the radial part exactly inside the monotone range for a start.
    let rd = (xd * xd + yd * yd).sqrt();
    let s_lim = radtan_r2_limit(c.k1, c.k2, c.k3);
    let pcoef = [1.0, c.k1, c.k2, c.k3, 0.0];
    let r0 = invert_odd_poly(&pcoef, &dcoef, rd, s_lim.sqrt())?;
    let (x0, y0) = if rd > 0.0 {
        (xd * r0 / rd, yd * r0 / rd)
    } else {
        (0.0, 0.0)
    };
    let (x, y) = newton_radtan(c, xd, yd, x0, y0)?;
    (x * x + y * y < s_lim).then_some((x, y))
}

/// Damped 2-D Newton iteration for `distort(x, y) = (xd, yd)` from `(x0, y0)`.
fn newton_radtan(c: &RadTan, xd: f64, yd: f64, x0: f64, y0: f64) -> Option<(f64, f64)> {
    let scale = 1.0 + xd.abs().max(yd.abs());
    let (mut x, mut y) = (x0, y0);
    let residual = |x: f64, y: f64| {
        let (fx, fy) = radtan_apply(c, x, y);
        (fx - xd).abs().max((fy - yd).abs())
    };
    let mut err = residual(x, y);
    for _ in 0..MAX_NEWTON {
        if !err.is_finite() {
            return None;
        }
        if err <= 1e-15 * scale {
            break;
        }
        let ((fx, fy), j) = radtan_with_jacobian(c, x, y);
        let (ex, ey) = (fx - xd, fy - yd);
        let det = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        if !(det.abs() > 1e-300) || !det.is_finite() {
            break;
        }
        let dx = (j[1][1] * ex - j[0][1] * ey) / det;
        let dy = (-j[1][0] * ex + j[0][0] * ey) / det;
        // Backtracking line search on the residual.
        let mut step = 1.0;
        let mut improved = false;
        for _ in 0..40 {
            let (nx, ny) = (x - step * dx, y - step * dy);
            let nerr = residual(nx, ny);
            if nerr < err {
                x = nx;
                y = ny;
                err = nerr;
                improved = true;
                break;
            }
            step *= 0.5;
        }
        if !improved {
            break;
        }
    }
    (err <= 1e-10 * scale && x.is_finite() && y.is_finite()).then_some((x, y))
}

/// `1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3`: derivative of the radial map `r (1 + k1 r^2 + ...)`.
#[inline]
pub(super) fn deriv_coeffs_radtan(k1: f64, k2: f64, k3: f64) -> [f64; 5] {
    [1.0, 3.0 * k1, 5.0 * k2, 7.0 * k3, 0.0]
}

/// Smallest `s = r^2` at which the radtan radial map stops increasing (`+inf` if never).
pub(super) fn radtan_r2_limit(k1: f64, k2: f64, k3: f64) -> f64 {
    first_positive_root(&deriv_coeffs_radtan(k1, k2, k3), f64::INFINITY).unwrap_or(f64::INFINITY)
}
