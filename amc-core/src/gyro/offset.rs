//! The time offset between a gyro log and the video, and the drift of the
//! two clocks.
//!
//! First over the log's whole span: at every offset on a [`COARSE_STEP`] grid
//! where the log covers the clip, the correlation of the video's angular
//! speed per frame interval with the gyro's over the same interval (a speed
//! is the same in any axes, so the mounting does not matter yet). Logs can
//! be minutes long, so the log's integral is first resampled on a uniform
//! [`GRID_STEP`] grid, where an interval's rotation costs two lookups.
//! Then to a fraction of a millisecond: the full fit's disagreement
//! ([`fit_mount`]) on a millisecond grid around the best speed match, then a
//! finer grid and the vertex of a parabola. The drift: the same refinement on
//! each quarter of the clip, and the slope of their offsets in time.

use super::glitch::median;
use super::integrate::GyroIntegral;
use super::mount::fit_mount;
use super::samples::VisionStep;
use nalgebra::Vector3;

/// Offsets tried over the log's span, seconds.
pub const COARSE_STEP: f64 = 0.002;
/// Resampling step of the log's integral for the coarse search, seconds.
const GRID_STEP: f64 = 0.0005;
/// Share of the clip's frame intervals the log must cover at an offset: a
/// flight controller armed after the camera started, or stopped before it,
/// covers part of the clip (the rest is the picture's alone).
pub const MIN_COVER: f64 = 0.5;

/// The log's integral on a uniform grid.
struct UniformIntegral {
    start: f64,
    values: Vec<Vector3<f64>>,
}

impl UniformIntegral {
    fn new(integral: &GyroIntegral) -> Self {
        let (a, b) = integral.span();
        let n = ((b - a) / GRID_STEP).floor() as usize + 1;
        let values = (0..n)
            .map(|i| integral.at(a + i as f64 * GRID_STEP).unwrap_or_default())
            .collect();
        Self { start: a, values }
    }

    fn at(&self, t: f64) -> Option<Vector3<f64>> {
        let x = (t - self.start) / GRID_STEP;
        if x < 0.0 {
            return None;
        }
        let i = x.floor() as usize;
        let f = x - i as f64;
        let (a, b) = (self.values.get(i)?, self.values.get(i + 1)?);
        Some(a + (b - a) * f)
    }
}

/// Pearson correlation of two series.
fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    if a.len() < 3 {
        return f64::NEG_INFINITY;
    }
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (dx, dy) = (x - ma, y - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    if saa <= 0.0 || sbb <= 0.0 {
        return f64::NEG_INFINITY;
    }
    sab / (saa * sbb).sqrt()
}

/// The correlation of the log's angular speeds with the video's at `offset`
/// (video time = log time + offset), over the intervals the log covers.
pub fn speed_correlation(integral: &GyroIntegral, steps: &[VisionStep], offset: f64) -> f64 {
    let (video, log): (Vec<f64>, Vec<f64>) = steps
        .iter()
        .filter_map(|s| {
            let g = integral.speed(s.t0 - offset, s.t1 - offset)?;
            Some((s.rotation.norm() / (s.t1 - s.t0), g))
        })
        .unzip();
    correlation(&video, &log)
}

/// The offsets (video time = log time + offset) whose gyro speeds correlate
/// best with the video's, searched over every offset at which the log covers
/// the clip: the [`CANDIDATES`] highest peaks (at least [`PEAK_GAP`] apart),
/// best first, with their correlations. Speeds alone cannot tell a motion
/// from its mirror image, so the full fit chooses among them.
pub fn coarse_offset(integral: &GyroIntegral, steps: &[VisionStep]) -> Vec<(f64, f64)> {
    let grid = UniformIntegral::new(integral);
    let (log0, log1) = integral.span();
    let (v0, v1) = (steps[0].t0, steps[steps.len() - 1].t1);
    let video: Vec<f64> = steps
        .iter()
        .map(|s| s.rotation.norm() / (s.t1 - s.t0))
        .collect();
    // A gyro speed far above what the video saw is a glitch: clamped, so
    // that one spike does not decide the correlation.
    let mut sorted = video.clone();
    sorted.sort_by(f64::total_cmp);
    let cap = 1.2 * sorted[(sorted.len() * 99 / 100).min(sorted.len() - 1)] + 0.05;
    // Offsets with the log covering the clip: log0 <= v0 - o, v1 - o <= log1,
    // widened by the share that may be left uncovered.
    let slack = (1.0 - MIN_COVER) * (v1 - v0);
    let (lo, hi) = (v1 - log1 - slack, v0 - log0 + slack);
    let offsets = (0..)
        .map(|k| lo + k as f64 * COARSE_STEP)
        .take_while(|&o| o <= hi)
        .count();
    // Each offset's score on its own buffers: the same scores on any number
    // of threads.
    let score = |k: usize, (a, b): &mut (Vec<f64>, Vec<f64>)| {
        let o = lo + k as f64 * COARSE_STEP;
        a.clear();
        b.clear();
        for (s, v) in steps.iter().zip(&video) {
            if let (Some(w0), Some(w1)) = (grid.at(s.t0 - o), grid.at(s.t1 - o)) {
                a.push(*v);
                b.push(((w1 - w0).norm() / (s.t1 - s.t0)).min(cap));
            }
        }
        let c = if (a.len() as f64) < MIN_COVER * steps.len() as f64 {
            f64::NEG_INFINITY
        } else {
            correlation(a, b)
        };
        (o, c)
    };
    let buffers = || {
        (
            Vec::with_capacity(steps.len()),
            Vec::with_capacity(steps.len()),
        )
    };
    #[cfg(feature = "parallel")]
    let scores: Vec<(f64, f64)> = {
        use rayon::prelude::*;
        (0..offsets)
            .into_par_iter()
            .map_init(buffers, |buf, k| score(k, buf))
            .collect()
    };
    #[cfg(not(feature = "parallel"))]
    let scores: Vec<(f64, f64)> = {
        let mut buf = buffers();
        (0..offsets).map(|k| score(k, &mut buf)).collect()
    };
    // Local maxima, highest first, kept apart.
    let mut peaks: Vec<(f64, f64)> = (0..scores.len())
        .filter(|&i| {
            let c = scores[i].1;
            c.is_finite()
                && (i == 0 || scores[i - 1].1 <= c)
                && (i + 1 == scores.len() || scores[i + 1].1 < c)
        })
        .map(|i| scores[i])
        .collect();
    peaks.sort_by(|x, y| y.1.total_cmp(&x.1));
    let mut chosen: Vec<(f64, f64)> = Vec::new();
    for p in peaks {
        if chosen.len() == CANDIDATES {
            break;
        }
        if chosen.iter().all(|q| (q.0 - p.0).abs() >= PEAK_GAP) {
            chosen.push(p);
        }
    }
    chosen
}

/// Correlation peaks the full fit chooses among.
pub const CANDIDATES: usize = 4;
/// Least distance between two candidate offsets, seconds.
const PEAK_GAP: f64 = 0.05;

/// The offset within `window` seconds of `around` where the full fit
/// disagrees least: a millisecond grid, then a tenth of one, then the vertex
/// of the parabola through the best and its neighbours.
pub fn refine_offset(
    integral: &GyroIntegral,
    steps: &[VisionStep],
    around: f64,
    window: f64,
) -> f64 {
    let cost = |o: f64| {
        let fit = fit_mount(integral, steps, o);
        let kept = fit.covered - fit.glitches;
        if (kept as f64) < MIN_COVER * 0.5 * steps.len() as f64 {
            f64::INFINITY
        } else {
            fit.cost / kept as f64
        }
    };
    let mut best = around;
    for (half, step) in [(window, 0.001), (0.0015, 0.0001)] {
        let n = (half / step).round() as i64;
        let center = best;
        let mut best_cost = f64::INFINITY;
        let grid: Vec<f64> = (-n..=n).map(|i| center + i as f64 * step).collect();
        for (o, c) in grid.iter().zip(costs(&grid, &cost)) {
            if c < best_cost {
                best_cost = c;
                best = *o;
            }
        }
        if half < window {
            // Sub-grid: the parabola through the best and its neighbours.
            let (cm, c0, cp) = (cost(best - step), best_cost, cost(best + step));
            let den = cm - 2.0 * c0 + cp;
            if den > 0.0 && cm.is_finite() && cp.is_finite() {
                best += 0.5 * step * (cm - cp) / den;
            }
        }
    }
    best
}

/// `cost` at each offset, in order (on the caller's rayon pool with the
/// `parallel` feature: each value is the same either way).
fn costs(offsets: &[f64], cost: &(impl Fn(f64) -> f64 + Sync)) -> Vec<f64> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        offsets.par_iter().map(|&o| cost(o)).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        offsets.iter().map(|&o| cost(o)).collect()
    }
}

/// The clocks' drift, parts per million: the offsets of the clip's parts
/// (a second or more each, four to sixteen of them, each refined around
/// `offset`) against their middle times, by the median of the pairwise slopes
/// (a part with a glitch or poor texture does not tilt it); 0 when the parts
/// are too short to tell or the slope is not clear of the offsets' own
/// scatter ([`DRIFT_SIGMAS`] standard errors): a spurious drift of a few ppm
/// moves the offset by tens of microseconds over a clip, which a fast shake
/// turns into per-frame error.
pub fn drift_ppm(integral: &GyroIntegral, steps: &[VisionStep], offset: f64) -> f64 {
    const MIN_STEPS: usize = 20;
    let parts = (steps.len() / 60).clamp(4, 16);
    let n = steps.len() / parts;
    if n < MIN_STEPS {
        return 0.0;
    }
    let points: Vec<(f64, f64)> = steps
        .chunks(n)
        .take(parts)
        .map(|part| {
            let mid = 0.5 * (part[0].t0 + part[part.len() - 1].t1);
            (mid, refine_offset(integral, part, offset, 0.003))
        })
        .collect();
    let mut slopes = Vec::new();
    for (i, a) in points.iter().enumerate() {
        for b in &points[i + 1..] {
            if b.0 > a.0 {
                slopes.push((b.1 - a.1) / (b.0 - a.0));
            }
        }
    }
    if slopes.is_empty() {
        return 0.0;
    }
    let slope = median(&mut slopes);
    let mut rest: Vec<f64> = points.iter().map(|(t, o)| o - slope * t).collect();
    let intercept = median(&mut rest);
    let mut residuals: Vec<f64> = points
        .iter()
        .map(|(t, o)| (o - slope * t - intercept).abs())
        .collect();
    let scale = 1.4826 * median(&mut residuals);
    let mt = points.iter().map(|p| p.0).sum::<f64>() / points.len() as f64;
    let spread: f64 = points.iter().map(|p| (p.0 - mt).powi(2)).sum();
    // With no scatter at all (an exact log) any slope is clear.
    let clear = spread > 0.0 && slope.abs() > DRIFT_SIGMAS * scale / spread.sqrt();
    if clear {
        slope * 1e6
    } else {
        0.0
    }
}

/// Standard errors a drift must clear to be kept.
pub const DRIFT_SIGMAS: f64 = 4.0;
