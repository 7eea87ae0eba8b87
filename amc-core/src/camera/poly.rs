//! Polynomials in `s = r^2` (radtan) or `t = theta^2` (fisheye): evaluation, the
//! monotonicity test behind the validity limits, real-root isolation and the safeguarded
//! inversion of odd polynomials used by the inverse maps.
//!
//! The validity limits are decided exactly but cheaply: a one-line sufficient bound
//! (sum of the negative terms of the derivative polynomial) settles almost every call;
//! only rays near the limit run the exact root isolation, which allocates nothing.

/// Maximum Newton iterations of the inverse maps.
pub(super) const MAX_NEWTON: usize = 50;

/// Solves `r * P(r^2) = target` for `r` in `[0, r_hi)`, where `D(r^2) = d/dr [r P(r^2)]` is
/// positive on `[0, r_hi)` (`r_hi` may be infinite). Safeguarded Newton (Newton steps that
/// leave the bracket become bisections). `None` if the target is not reached below `r_hi`.
pub(super) fn invert_odd_poly(p: &[f64; 5], d: &[f64; 5], target: f64, r_hi: f64) -> Option<f64> {
    if !(target.is_finite() && target >= 0.0) || r_hi.is_nan() {
        return None;
    }
    let g = |r: f64| r * poly_eval(p, r * r) - target;
    if target == 0.0 {
        return Some(0.0);
    }
    // Bracket [lo, hi] with g(lo) < 0 <= g(hi).
    let hi = if r_hi.is_finite() {
        if !(g(r_hi) > 0.0) {
            return None;
        }
        r_hi
    } else {
        let mut hi = 1.0_f64.max(target);
        let mut n = 0;
        while !(g(hi) > 0.0) {
            hi *= 2.0;
            n += 1;
            if n > 200 || !hi.is_finite() {
                return None;
            }
        }
        hi
    };
    let (mut lo, mut hi) = (0.0_f64, hi);
    let mut r = target.min(0.5 * (lo + hi)).max(0.0);
    for _ in 0..200 {
        let gr = g(r);
        if !gr.is_finite() {
            return None;
        }
        if gr == 0.0 {
            return Some(r);
        }
        if gr < 0.0 {
            lo = r;
        } else {
            hi = r;
        }
        let dg = poly_eval(d, r * r);
        let newton = r - gr / dg;
        let next = if dg > 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if (next - r).abs() <= 1e-15 * (1.0 + r) || hi - lo <= 1e-15 * (1.0 + hi) {
            return (next < r_hi).then_some(next);
        }
        r = next;
    }
    (r < r_hi).then_some(r)
}

/// Horner evaluation of `c[0] + c[1] t + ... + c[4] t^4`.
#[inline]
pub(super) fn poly_eval(c: &[f64; 5], t: f64) -> f64 {
    (((c[4] * t + c[3]) * t + c[2]) * t + c[1]) * t + c[0]
}

/// True when the derivative polynomial `c` (with `c[0] = 1`) is positive on `[0, t]`,
/// i.e. the distortion map is strictly increasing up to `t`. Cheap sufficient bound first
/// (drop the positive terms), exact critical-point test only when that is inconclusive.
#[inline]
pub(super) fn monotone_on(c: &[f64; 5], t: f64) -> bool {
    if !(t >= 0.0 && t.is_finite()) {
        return false;
    }
    let neg = |v: f64| v.min(0.0);
    let bound = 1.0 + t * (neg(c[1]) + t * (neg(c[2]) + t * (neg(c[3]) + t * neg(c[4]))));
    if bound > 0.0 {
        return true;
    }
    monotone_on_exact(c, t)
}

/// Exact version of [`monotone_on`]: the minimum of a polynomial on an interval is at an
/// end point or at a root of its derivative.
#[cold]
fn monotone_on_exact(c: &[f64; 5], t: f64) -> bool {
    if !(poly_eval(c, 0.0) > 0.0 && poly_eval(c, t) > 0.0) {
        return false;
    }
    let mut crit = [0.0; 4];
    let n = if c[4] == 0.0 {
        // Cubic (radtan): critical points in closed form, no iteration.
        quadratic_roots(c[1], 2.0 * c[2], 3.0 * c[3], &mut crit)
    } else {
        roots_in(&derivative(c), 0.0, t, &mut crit)
    };
    crit[..n]
        .iter()
        .all(|&s| !(s > 0.0 && s < t) || poly_eval(c, s) > 0.0)
}

/// Real roots of `a + b s + c s^2` (any order, at most 2) written to `out`.
#[inline]
fn quadratic_roots(a: f64, b: f64, c: f64, out: &mut [f64; 4]) -> usize {
    if c == 0.0 {
        if b == 0.0 {
            return 0;
        }
        out[0] = -a / b;
        return 1;
    }
    let disc = b * b - 4.0 * a * c;
    if !(disc >= 0.0) {
        return 0;
    }
    // Numerically stable form: q = -(b + sign(b) sqrt(disc)) / 2, roots q/c and a/q.
    let q = -0.5 * (b + disc.sqrt().copysign(b));
    out[0] = q / c;
    if q == 0.0 {
        return 1;
    }
    out[1] = a / q;
    2
}

/// Smallest root of `c` (with `c[0] > 0`) in `(0, hi]`; `hi` may be infinite, in which
/// case the Cauchy bound on the root magnitudes is used.
pub(super) fn first_positive_root(c: &[f64; 5], hi: f64) -> Option<f64> {
    if c.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let hi = if hi.is_finite() {
        hi
    } else {
        let n = degree(c);
        if n == 0 {
            return None;
        }
        1.0 + c[..n].iter().map(|v| (v / c[n]).abs()).fold(0.0, f64::max)
    };
    let mut roots = [0.0; 4];
    let n = roots_in(c, 0.0, hi, &mut roots);
    roots[..n].iter().copied().find(|&r| r > 0.0)
}

/// Degree of the polynomial (index of the last non-zero coefficient).
#[inline]
fn degree(c: &[f64; 5]) -> usize {
    let mut d = 4;
    while d > 0 && c[d] == 0.0 {
        d -= 1;
    }
    d
}

/// Coefficients of the derivative.
#[inline]
fn derivative(c: &[f64; 5]) -> [f64; 5] {
    [c[1], 2.0 * c[2], 3.0 * c[3], 4.0 * c[4], 0.0]
}

/// All real roots of `c` in `[lo, hi]`, ascending (at most 4), written to `out`.
/// Splits the interval at the roots of the derivative (found recursively) into monotone
/// pieces and bisects each piece that changes sign. Roots of even multiplicity that do not
/// change sign are found only when they coincide with a critical point (which they do).
fn roots_in(c: &[f64; 5], lo: f64, hi: f64, out: &mut [f64; 4]) -> usize {
    if !(lo <= hi) {
        return 0;
    }
    let deg = degree(c);
    if deg == 0 {
        return 0;
    }
    if deg == 1 {
        let r = -c[0] / c[1];
        if r >= lo && r <= hi {
            out[0] = r;
            return 1;
        }
        return 0;
    }
    let mut crit = [0.0; 4];
    let nc = roots_in(&derivative(c), lo, hi, &mut crit);
    let mut n = 0;
    let mut push = |r: f64, n: &mut usize| {
        if *n < 4 && (*n == 0 || out[*n - 1] < r) {
            out[*n] = r;
            *n += 1;
        }
    };
    let mut a = lo;
    let mut fa = poly_eval(c, lo);
    if fa == 0.0 {
        push(lo, &mut n);
    }
    for b in crit[..nc].iter().copied().chain(std::iter::once(hi)) {
        if b <= a {
            continue;
        }
        let fb = poly_eval(c, b);
        if fb == 0.0 {
            push(b, &mut n);
        } else if fa != 0.0 && (fa < 0.0) != (fb < 0.0) {
            push(bisect(c, a, b, fa), &mut n);
        }
        a = b;
        fa = fb;
    }
    n
}

/// Bisection for a sign change of `c` on `[a, b]` (`fa = c(a)`), to full precision.
fn bisect(c: &[f64; 5], mut a: f64, mut b: f64, fa: f64) -> f64 {
    let neg_a = fa < 0.0;
    for _ in 0..2100 {
        let m = 0.5 * (a + b);
        if !(m > a && m < b) {
            break;
        }
        let fm = poly_eval(c, m);
        if fm == 0.0 {
            return m;
        }
        if (fm < 0.0) == neg_a {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}
