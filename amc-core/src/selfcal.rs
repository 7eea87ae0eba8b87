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
/// timestamps in seconds), e.g. the first 2-3 seconds of a clip.
pub fn estimate_hfov(
    frames: &[(FrameRef<'_>, f64)],
    track_width: usize,
    tracker: &TrackerParams,
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
    // at once (the grid and the last three) give the same values.
    let score_of = |hfov: f64| -> Result<f64, AmcError> {
        let cam = CameraModel::pinhole_hfov(w, h, hfov)?;
        let track_cam = TrackingFrontend::new(&cam, track_width)?.camera().clone();
        let mut tr = Tracker::new(&track_cam, tracker.clone())?;
        let (mut sum, mut n) = (0.0, 0usize);
        for (p, &t) in pyramids.iter().zip(&times) {
            let (_, info) = tr.track(p, t);
            if info.iterations > 0 && info.rms_residual.is_finite() {
                sum += (info.rms_residual as f64).powi(2);
                n += 1;
            }
        }
        Ok(if n > 0 { sum / n as f64 } else { f64::INFINITY })
    };
    let mut curve = Vec::new();
    let scores = |hfovs: &[f64], curve: &mut Vec<(f64, f64)>| -> Result<Vec<f64>, AmcError> {
        let got = scores_of(hfovs, &score_of)?;
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
    let grid: Vec<(f64, f64)> = lfs
        .iter()
        .copied()
        .zip(scores(&hfovs, &mut curve)?)
        .collect();
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
        |lf: f64| score_of(to_hfov(lf.exp())),
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
