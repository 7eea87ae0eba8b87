//! The smoother that holds the gyro's chain to the picture: `z` minimizing
//! `sum_i w_i |y_i - z_i|^2 + lambda sum_i |z_{i+1} - z_i|^2`, the exact
//! smoother of a random walk (the chain's integrated noise, `lambda` =
//! vision's variance over the gyro's per step) seen through white noise
//! (vision's error). A tridiagonal system, solved in `O(n)`; weights 0 bridge
//! gaps. Robust: samples far from the others' fit are weighted down (Huber).

use super::glitch::median;

/// Pulled toward 0 so that all-zero weights still solve.
const RIDGE: f64 = 1e-12;
/// Huber's constant, in robust standard deviations.
const HUBER: f64 = 2.5;

/// The weighted smoother of one axis (see the module's docs).
pub fn random_walk_smoother(y: &[f64], w: &[f64], lambda: f64) -> Vec<f64> {
    let n = y.len();
    if n == 0 {
        return Vec::new();
    }
    // Thomas's algorithm on the symmetric tridiagonal W + lambda D^T D
    // (off-diagonal -lambda).
    let diag = |i: usize| {
        let links = usize::from(i > 0) + usize::from(i + 1 < n);
        w[i] + RIDGE + lambda * links as f64
    };
    let mut c = vec![0.0; n];
    let mut z = vec![0.0; n];
    let mut denom = diag(0);
    c[0] = -lambda / denom;
    z[0] = w[0] * y[0] / denom;
    for i in 1..n {
        denom = diag(i) + lambda * c[i - 1];
        c[i] = -lambda / denom;
        z[i] = (w[i] * y[i] + lambda * z[i - 1]) / denom;
    }
    for i in (0..n - 1).rev() {
        z[i] -= c[i] * z[i + 1];
    }
    z
}

/// [`random_walk_smoother`] on three axes, with weights lowered (Huber)
/// where a sample lies far from the others' fit, in `rounds` reweightings.
pub fn smooth_robust(y: &[[f64; 3]], w: &[f64], lambda: f64, rounds: usize) -> Vec<[f64; 3]> {
    let mut weights = w.to_vec();
    let mut z = vec![[0.0; 3]; y.len()];
    for round in 0..=rounds {
        for axis in 0..3 {
            let ya: Vec<f64> = y.iter().map(|v| v[axis]).collect();
            for (zi, v) in z
                .iter_mut()
                .zip(random_walk_smoother(&ya, &weights, lambda))
            {
                zi[axis] = v;
            }
        }
        if round == rounds {
            break;
        }
        let r: Vec<f64> = y.iter().zip(&z).map(|(y, z)| distance(y, z)).collect();
        let mut kept: Vec<f64> = r
            .iter()
            .zip(w)
            .filter(|(_, w)| **w > 0.0)
            .map(|(r, _)| *r)
            .collect();
        if kept.is_empty() {
            break;
        }
        let limit = HUBER * (1.4826 * median(&mut kept)).max(1e-12);
        for ((wt, w0), r) in weights.iter_mut().zip(w).zip(&r) {
            *wt = if *r > limit { w0 * limit / r } else { *w0 };
        }
    }
    z
}

fn distance(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(seed: &mut u64) -> f64 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }

    /// A constant passes at any lambda, and weights 0 are bridged by it.
    #[test]
    fn constants_pass_and_gaps_bridge() {
        let y = vec![0.25; 200];
        let mut w = vec![1.0; 200];
        for wi in &mut w[80..120] {
            *wi = 0.0;
        }
        for lambda in [0.0, 1.0, 1e4, 1e8] {
            for z in random_walk_smoother(&y, &w, lambda)[..80].iter() {
                assert!((z - 0.25).abs() < 1e-6, "lambda {lambda}: {z}");
            }
            if lambda > 0.0 {
                for z in random_walk_smoother(&y, &w, lambda) {
                    assert!((z - 0.25).abs() < 1e-6, "lambda {lambda}: {z}");
                }
            }
        }
    }

    /// A random walk seen through white noise: the smoother at lambda =
    /// noise variance over step variance comes closer to the walk than the
    /// observations do.
    #[test]
    fn recovers_a_random_walk_from_noisy_observations() {
        let (mut seed, mut walk, mut truth, mut y) = (7u64, 0.0, Vec::new(), Vec::new());
        let (step, obs) = (0.01, 0.1);
        for _ in 0..2000 {
            walk += step * noise(&mut seed) * 12f64.sqrt();
            truth.push(walk);
            y.push(walk + obs * noise(&mut seed) * 12f64.sqrt());
        }
        let z = random_walk_smoother(&y, &vec![1.0; 2000], (obs / step).powi(2));
        let rms = |a: &[f64], b: &[f64]| {
            (a.iter().zip(b).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
        };
        assert!(
            rms(&z, &truth) < 0.4 * rms(&y, &truth),
            "{} vs {}",
            rms(&z, &truth),
            rms(&y, &truth)
        );
    }

    /// An outlier barely moves the robust fit.
    #[test]
    fn robust_fit_ignores_an_outlier() {
        let mut y: Vec<[f64; 3]> = vec![[0.1, 0.0, 0.0]; 100];
        y[50][1] = 1.0;
        let z = smooth_robust(&y, &vec![1.0; 100], 10.0, 3);
        assert!(z[50][1].abs() < 0.02, "{}", z[50][1]);
    }
}
