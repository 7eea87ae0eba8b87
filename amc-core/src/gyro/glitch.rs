//! What the log says of itself: its white noise, and the samples where its
//! signal breaks (a spike's edges, a saturation's onset, a dropout, a gap in
//! time). A real camera's rotation is smooth at a gyro's rate (a 20 Hz shake
//! changes little in a millisecond), so a break is a jump far beyond the
//! samples' typical curvature. Fusion needs both: the noise weighs the gyro
//! against the picture, and where the two disagree the breaks tell whose
//! fault it is (a disagreement with no break near it is the picture's).

use super::samples::GyroSamples;

/// A jump this many robust standard deviations of the samples' second
/// differences is a break.
const BREAK_SIGMAS: f64 = 12.0;
/// ... and at least this large, rad/s.
const BREAK_FLOOR_RAD_S: f64 = 0.5;
/// A gap in time this many times the median sample interval is a break.
const GAP_INTERVALS: f64 = 3.0;

/// The white noise of each axis, rad/s (standard deviation), from the
/// samples' fourth differences (`70 sigma^2` for white noise; a smooth
/// motion's share is negligible at a gyro's rate), robustly.
pub fn noise_rad_s(gyro: &GyroSamples) -> f64 {
    let w = &gyro.w;
    if w.len() < 5 {
        return 0.0;
    }
    let mut d: Vec<f64> = Vec::with_capacity(3 * (w.len() - 4));
    for i in 0..w.len() - 4 {
        let d4 = w[i] - 4.0 * w[i + 1] + 6.0 * w[i + 2] - 4.0 * w[i + 3] + w[i + 4];
        d.extend(d4.iter().map(|v| v.abs()));
    }
    median(&mut d) * 1.4826 / 70f64.sqrt()
}

/// Log times where the signal breaks, in order.
pub fn breaks(gyro: &GyroSamples) -> Vec<f64> {
    let (t, w) = (&gyro.t, &gyro.w);
    let n = t.len();
    if n < 3 {
        return Vec::new();
    }
    let d2: Vec<f64> = (1..n - 1)
        .map(|i| (w[i + 1] - 2.0 * w[i] + w[i - 1]).amax())
        .collect();
    let mut sorted = d2.clone();
    let limit = (BREAK_SIGMAS * 1.4826 * median(&mut sorted)).max(BREAK_FLOOR_RAD_S);
    let mut dt: Vec<f64> = t.windows(2).map(|p| p[1] - p[0]).collect();
    let gap = GAP_INTERVALS * median(&mut dt);
    let mut out: Vec<f64> = (1..n - 1)
        .filter(|&i| d2[i - 1] > limit)
        .map(|i| t[i])
        .collect();
    out.extend(
        t.windows(2)
            .filter(|p| p[1] - p[0] > gap)
            .flat_map(|p| [p[0], p[1]]),
    );
    out.sort_by(f64::total_cmp);
    out
}

/// The median of `v` (reordered), 0 when empty.
pub(super) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let k = v.len() / 2;
    *v.select_nth_unstable_by(k, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn shake(rate: f64, seconds: f64, noise: f64) -> GyroSamples {
        let mut seed = 3u64;
        let mut g = GyroSamples::default();
        for i in 0..(rate * seconds) as usize {
            let t = i as f64 / rate;
            let mut n = || {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 12f64.sqrt() * noise
            };
            let s = (t * 16.0 * std::f64::consts::TAU).sin() * 5.0;
            g.t.push(t);
            g.w.push(Vector3::new(s + n(), 0.5 * s + n(), -s + n()));
        }
        g
    }

    /// The noise of a 16 Hz, 5 rad/s shake with 0.03 rad/s of noise.
    #[test]
    fn measures_the_noise_under_a_fast_shake() {
        let est = noise_rad_s(&shake(1000.0, 3.0, 0.03));
        assert!((est - 0.03).abs() < 0.005, "{est}");
    }

    /// A spike's two edges and a dropout's gap are breaks; the shake is not.
    #[test]
    fn finds_a_spike_and_a_gap() {
        let mut g = shake(1000.0, 3.0, 0.03);
        assert!(breaks(&g).is_empty(), "{:?}", breaks(&g));
        for w in &mut g.w[1000..1030] {
            w.x += 8.0;
        }
        g.t.drain(2000..2040);
        g.w.drain(2000..2040);
        let b = breaks(&g);
        assert!(b.iter().any(|t| (t - 1.0).abs() < 0.003), "{b:?}");
        assert!(b.iter().any(|t| (t - 1.03).abs() < 0.003), "{b:?}");
        assert!(b.iter().any(|t| (t - 2.04).abs() < 0.003), "{b:?}");
    }
}
