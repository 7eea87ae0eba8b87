//! Focal-length self-calibration from the footage (`--fov auto`).
//!
//! Under a pure rotation, frames align exactly only through the true intrinsics:
//! with a wrong focal length `f'` the rotational flow field
//! `u_dot = f (1 + x^2) w_y - f x y w_x - f y w_z` (and its `v` twin) cannot be
//! matched by any rotation, most visibly toward the image edges and under roll.
//! So the estimate is the horizontal field of view whose tracking leaves the
//! least photometric error:
//! ```text
//! hfov* = argmin_hfov  mean_j  rms_residual_j(hfov)^2
//! ```
//! searched on a coarse grid, then refined by golden-section search. Pyramids of
//! a pinhole source do not depend on the focal length, so they are built once.
//! Small, translation-like shakes constrain `f` only weakly (a pan of `theta`
//! looks like a shift of `f theta` to first order); roll and large rotations
//! constrain it well. See the README for measured accuracy.

use crate::camera::CameraModel;
use crate::error::AmcError;
use crate::frontend::TrackingFrontend;
use crate::image::FrameRef;
use crate::minimize::golden_section_paired;
use crate::pyramid::Pyramid;
use crate::tracker::{Tracker, TrackerParams};

/// Search range of the horizontal field of view, degrees.
pub const HFOV_RANGE_DEG: (f64, f64) = (20.0, 160.0);
/// Frames needed for a meaningful estimate.
pub const MIN_FRAMES: usize = 10;

/// Result of the self-calibration.
#[derive(Clone, Debug, PartialEq)]
pub struct FocalEstimate {
    /// Estimated horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// The pinhole camera with that field of view.
    pub camera: CameraModel,
    /// `(hfov_deg, score)` pairs evaluated, for diagnostics.
    pub curve: Vec<(f64, f64)>,
    /// Whether the footage constrains the focal length: the score 20% off in
    /// focal length is at least [`CONFIDENCE_RATIO`] times the minimum.
    pub confident: bool,
}

/// Score ratio (20% away in focal length vs the minimum) above which the
/// estimate is trusted: rotation-only footage clears it by far, footage
/// dominated by translation does not (see `docs/core-history.md#selfcal-confidence-ratio`).
pub const CONFIDENCE_RATIO: f64 = 1.2;

/// Estimates the focal length of a pinhole camera from `frames` (with their
/// timestamps in seconds), e.g. the first 2-3 seconds of a clip, read out
/// over `readout_s` seconds (0: a global shutter). With a rolling shutter
/// each field of view is scored with the readout's model: fast motion bends
/// such frames in a way no rotation of a global shutter explains, which
/// flattened the scores into a fallback (250 deg/s over 12 ms, 640x360:
/// 70 deg instead of 100; see docs/accuracy.md).
pub fn estimate_hfov(
    frames: &[(FrameRef<'_>, f64)],
    track_width: usize,
    tracker: &TrackerParams,
    readout_s: f64,
) -> Result<FocalEstimate, AmcError> {
    if frames.len() < MIN_FRAMES {
        return Err(AmcError::TooFewFrames {
            needed: MIN_FRAMES,
            got: frames.len(),
        });
    }
    let (w, h) = (frames[0].0.width, frames[0].0.height);
    let probe = CameraModel::pinhole_hfov(w, h, 60.0)?;
    let frontend = TrackingFrontend::new(&probe, track_width)?;
    let levels = Tracker::new(frontend.camera(), tracker.clone())?.levels();
    if let Some((f, _)) = frames.iter().find(|(f, _)| f.width != w || f.height != h) {
        return Err(AmcError::FrameSizeChanged {
            expected_w: w,
            expected_h: h,
            actual_w: f.width,
            actual_h: f.height,
        });
    }
    let pyramids = pyramids_of(frames, &frontend, levels);
    let times: Vec<f64> = frames.iter().map(|(_, t)| *t).collect();
    // One field of view's score: each its own tracker, so that scores run
    // at once (the grid and the last three) give the same values. A score
    // stops once its sum shows it can only end above `bound` (the frames' mean
    // with every frame counted is a lower bound of it) and returns that
    // lower bound: it then loses every comparison it takes part in.
    let frames_n = pyramids.len() as f64;
    let score_of = |hfov: f64, bound: f64| -> Result<f64, AmcError> {
        let cam = CameraModel::pinhole_hfov(w, h, hfov)?;
        let track_cam = TrackingFrontend::new(&cam, track_width)?.camera().clone();
        let mut tr = Tracker::new(&track_cam, tracker.clone())?;
        if readout_s > 0.0 {
            tr.set_rolling(crate::shutter::RowTime::new(&cam, &track_cam), readout_s);
        }
        let (mut sum, mut n) = (0.0, 0usize);
        for (p, &t) in pyramids.iter().zip(&times) {
            let (_, info) = tr.track(p, t);
            if info.iterations > 0 && info.rms_residual.is_finite() {
                sum += (info.rms_residual as f64).powi(2);
                n += 1;
                if sum / frames_n > bound {
                    return Ok(sum / frames_n);
                }
            }
        }
        Ok(if n > 0 { sum / n as f64 } else { f64::INFINITY })
    };
    let mut curve = Vec::new();
    let scores = |hfovs: &[f64], curve: &mut Vec<(f64, f64)>| -> Result<Vec<f64>, AmcError> {
        let got = scores_of(hfovs, &|h| score_of(h, f64::INFINITY))?;
        curve.extend(hfovs.iter().copied().zip(got.iter().copied()));
        Ok(got)
    };

    // Coarse grid, uniform in log focal length (where the error is smoother).
    let (lo, hi) = HFOV_RANGE_DEG;
    let to_f = |hfov: f64| 1.0 / (hfov.to_radians() / 2.0).tan();
    let to_hfov = |f: f64| 2.0 * (1.0 / f).atan().to_degrees();
    let (lf_lo, lf_hi) = (to_f(hi).ln(), to_f(lo).ln());
    const GRID: usize = 15;
    let lfs: Vec<f64> = (0..GRID)
        .map(|i| lf_lo + (lf_hi - lf_lo) * i as f64 / (GRID - 1) as f64)
        .collect();
    let hfovs: Vec<f64> = lfs.iter().map(|lf| to_hfov(lf.exp())).collect();
    let grid_scores = grid_scores_of(&hfovs, &score_of)?;
    curve.extend(hfovs.iter().copied().zip(grid_scores.iter().copied()));
    let grid: Vec<(f64, f64)> = lfs.iter().copied().zip(grid_scores).collect();
    let best = grid
        .iter()
        .enumerate()
        .min_by(|a, b| a.1 .1.total_cmp(&b.1 .1))
        .map_or(0, |(i, _)| i);
    let (a, b) = (
        grid[best.saturating_sub(1)].0,
        grid[(best + 1).min(GRID - 1)].0,
    );
    // Golden-section refinement in log focal length.
    let lf_best = golden_section_paired(
        |lf: f64, bound: f64| score_of(to_hfov(lf.exp()), bound),
        a,
        b,
        12,
        |lf, s| curve.push((to_hfov(lf.exp()), s)),
    )?;
    let hfov_deg = to_hfov(lf_best.exp());
    let last = scores(
        &[
            hfov_deg,
            to_hfov(lf_best.exp() / 1.2),
            to_hfov(lf_best.exp() * 1.2),
        ],
        &mut curve,
    )?;
    let (best_score, wider, narrower) = (last[0], last[1], last[2]);
    let confident = best_score.is_finite() && wider.min(narrower) >= CONFIDENCE_RATIO * best_score;
    curve.sort_by(|x, y| x.0.total_cmp(&y.0));
    Ok(FocalEstimate {
        hfov_deg,
        camera: CameraModel::pinhole_hfov(w, h, hfov_deg)?,
        curve,
        confident,
    })
}

/// The tracking pyramids of `frames` (at once on rayon's threads with the
/// `parallel` feature, each with its own copy of `frontend`: the same
/// pyramids either way).
fn pyramids_of(
    frames: &[(FrameRef<'_>, f64)],
    frontend: &TrackingFrontend,
    levels: usize,
) -> Vec<Pyramid> {
    let prepare = |frontend: &mut TrackingFrontend, (f, _): &(FrameRef<'_>, f64)| {
        let mut p = Pyramid::default();
        frontend.prepare(f, &mut p, levels);
        p
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        frames
            .par_iter()
            .map_init(|| frontend.clone(), prepare)
            .collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut frontend = frontend.clone();
        frames.iter().map(|f| prepare(&mut frontend, f)).collect()
    }
}

/// The grid's scores, in its order: each exact where it can be the grid's
/// best, else a lower bound above a score already found (see `score_of` in
/// [`estimate_hfov`]), so the best and its place are the same as with every
/// score exact. The middle of the range, where cameras' fields of view
/// are, goes first: its scores bound the rest, and the far ends (whose
/// tracking converges worst and costs most) mostly stop early. On rayon's
/// threads with the `parallel` feature, each taking the next field of view.
fn grid_scores_of(
    hfovs: &[f64],
    score: &(impl Fn(f64, f64) -> Result<f64, AmcError> + Sync),
) -> Result<Vec<f64>, AmcError> {
    use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
    let n = hfovs.len();
    let mid = n / 2;
    // mid, mid - 1, mid + 1, mid - 2, ...
    let order: Vec<usize> = (0..n)
        .map(|k| {
            if k % 2 == 1 {
                mid - k.div_ceil(2)
            } else {
                mid + k / 2
            }
        })
        .collect();
    // The best exact score so far (non-negative, so its bits order as it does).
    let best = AtomicU64::new(f64::INFINITY.to_bits());
    let next = AtomicUsize::new(0);
    let work = || -> Vec<(usize, Result<f64, AmcError>)> {
        let mut done = Vec::new();
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(&i) = order.get(k) else {
                return done;
            };
            let bound = f64::from_bits(best.load(Ordering::Relaxed));
            let got = score(hfovs[i], bound);
            if let Ok(v) = got {
                if v <= bound {
                    best.fetch_min(v.to_bits(), Ordering::Relaxed);
                }
            }
            done.push((i, got));
        }
    };
    #[cfg(feature = "parallel")]
    let done: Vec<_> = {
        use rayon::prelude::*;
        (0..rayon::current_num_threads())
            .into_par_iter()
            .flat_map_iter(|_| work())
            .collect()
    };
    #[cfg(not(feature = "parallel"))]
    let done = work();
    let mut out = vec![f64::INFINITY; n];
    for (i, got) in done {
        out[i] = got?;
    }
    Ok(out)
}

/// `score` at each field of view, in order (at once on rayon's threads with
/// the `parallel` feature: each value is the same either way).
fn scores_of(
    hfovs: &[f64],
    score: &(impl Fn(f64) -> Result<f64, AmcError> + Sync),
) -> Result<Vec<f64>, AmcError> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        hfovs.par_iter().map(|&h| score(h)).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        hfovs.iter().map(|&h| score(h)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// Scores stopped above the best found so far leave the grid's best, and
    /// its place, as every score exact would; the far ends stop early.
    #[test]
    fn grid_scores_stopped_early_keep_the_best_in_its_place() {
        let hfovs: Vec<f64> = (0..15).map(|i| 20.0 + 10.0 * i as f64).collect();
        for truth in [25.0, 71.0, 90.0, 104.0, 158.0] {
            let exact = |h: f64| 1.0 + ((h - truth) / 10.0).powi(2);
            let stopped = AtomicUsize::new(0);
            // As `score_of` does: a sum over 90 frames, stopped once its
            // mean over all of them is above the bound.
            let score = |h: f64, bound: f64| -> Result<f64, AmcError> {
                let per_frame = exact(h);
                let mut sum = 0.0;
                for _ in 0..90 {
                    sum += per_frame;
                    if sum / 90.0 > bound {
                        stopped.fetch_add(1, Ordering::Relaxed);
                        return Ok(sum / 90.0);
                    }
                }
                Ok(sum / 90.0)
            };
            let got = grid_scores_of(&hfovs, &score).unwrap();
            let argmin = |v: &[f64]| {
                v.iter()
                    .enumerate()
                    .min_by(|a, b| a.1.total_cmp(b.1))
                    .map(|(i, s)| (i, s.to_bits()))
            };
            let all: Vec<f64> = hfovs
                .iter()
                .map(|&h| score(h, f64::INFINITY).unwrap())
                .collect();
            assert_eq!(argmin(&got), argmin(&all), "true field of view {truth}");
            assert!(
                stopped.load(Ordering::Relaxed) > 0,
                "none stopped at {truth}"
            );
        }
    }
}
