//! Rotation tracker: inverse-compositional Lucas-Kanade (Baker & Matthews 2004)
//! over SO(3), coarse to fine.
//!
//! ## Model
//! A template `T` (frame `k`) and the current frame `I` (frame `j`) are related by
//! a pure rotation `R = R_{k,j}`. A template pixel `p` with normalized ray
//! `x = K^-1 p = (x, y, 1)` sees the same scene point as pixel `pi(K R^T x)` of `I`:
//! ```text
//! E(R) = sum_p rho( I(pi(K R^T x_p)) - T(p) )
//! ```
//! ## Inverse-compositional Gauss-Newton step
//! Warp the *template* by a small rotation `delta in so(3)`:
//! `W(p; delta) = pi(K exp(delta) x)`. With `exp(delta) x ~ x - [x]x delta` and
//! `u = fx x + s y + cx`, `v = fy y + cy` the Jacobian at `delta = 0` is
//! ```text
//! dx/d delta = (-x y, 1 + x^2, -y)        dy/d delta = (-(1 + y^2), x y, x)
//! du/d delta = fx dx/d delta + s dy/d delta      dv/d delta = fy dy/d delta
//! ```
//! so the steepest-descent image `SD_p = grad T(p) . dW/d delta` and the
//! Gauss-Newton Hessian `H = sum_p w_p SD_p SD_p^T` depend on the template only
//! (precomputed at each template reset). With residual `e_p = I(W(p; R)) - T(p)`:
//! ```text
//! delta = H^-1 sum_p w_p SD_p e_p,        R <- exp(delta) R
//! ```
//! (`T(exp(delta) y) = I(R^T exp(-delta) y)` for all `y`, hence
//! `R_new^T = R^T exp(-delta)`.)
//!
//! ## Robustness
//! * Huber loss `rho` with IRLS weights `w_p = min(1, c / |e_p|)`: moving objects,
//!   the dashboard of a car, transmission glitches.
//! * Backtracking line search on the mean robust loss: a step is halved until the
//!   loss does not increase, so the estimate never gets worse.
//! * Coarse-to-fine pyramid: a 2x2 box pyramid down to ~40 px wide gives a
//!   basin of tens of pixels at full resolution (300 deg/s at 60 fps).
//! * Warm start: the best (lowest coarse-level loss) of the previous estimate,
//!   a constant angular-velocity prediction, and the template pose itself.
//!   Flapping-wing shake at 12-20 Hz sampled at 60 fps reverses within 2-3
//!   frames, so a constant-velocity guess alone can be worse than none.
//! * Camera-fixed regions (a car's dashboard, an FPV on-screen display,
//!   propellers in view) agree with "no rotation" and pull a least-squares
//!   estimate toward zero. After each frame, every template pixel whose image
//!   moved by more than [`STATIC_MIN_DISPLACEMENT_PX`] votes: if the current
//!   frame at the *same* location explains it much better than at the rotated
//!   location (`|e_id| < |e_rot| / 2`), it is camera-fixed. Votes are averaged
//!   per image location with an exponential moving average, and locations whose
//!   average exceeds [`STATIC_THRESHOLD`] are left out of later templates.
//! * Recovery: when a frame's final residual is far above the typical residual
//!   (a wrong local minimum, e.g. a 6 deg jerk), a grid of pan/tilt offsets is
//!   scored at the coarsest level, the best is refined coarse to fine, and the
//!   result with the lower residual is kept. A frame that still tracks badly
//!   never becomes the template (the reset waits for a good frame), so one bad
//!   frame cannot bake its error into every later estimate.
//! * Template handover: the frame after each template reset is tracked against
//!   the outgoing template too, and the new template's orientation is set so
//!   that the two agree on it ([`Tracker::hand_over`]). Every template carries
//!   its own small bias into all the frames aligned to it; handed over, that
//!   bias no longer steps the orientation at each reset, so it neither shows
//!   as a jump between two frames nor adds up, template after template.
//! * Only pixels valid in both images count (`NaN` marks invalid pixels).
//! * Per level, only the strongest-gradient pixel of each small block is used
//!   (at most `max_points`): low-gradient pixels carry almost no information
//!   about the rotation, and skipping them makes tracking several times faster.
//!
//! ## Rolling shutter
//! With [`Tracker::set_rolling`], each frame's motion during its readout,
//! `a(s) = s phi + s^2 psi + s^3 chi + s^4 xi` ([`IntraFrame`], `s` the readout
//! fraction of a row), is estimated with its mid-readout rotation:
//! * template rays are rectified into the template's mid-readout camera,
//!   `y = exp(a_k(s_p)) x_p`;
//! * a ray lands in the current frame at `pi(K exp(-a(s)) R^T y)`, `s` the
//!   readout fraction of the landing row (a fixed point: two steps from the
//!   mid-readout projection and an extrapolation; a level's later evaluations
//!   take one step from the last landing, and keep its first Gauss-Newton
//!   matrix until a step moves the points far, [`WarmStart`]); through a
//!   distorted lens the landing row's readout fraction is sampled from a
//!   table per level ([`RowTime::level_table`]);
//! * the Gauss-Newton step has up to 15 parameters ([`Eval::pose_step`]): the
//!   rotation's inverse-compositional step and additive steps of the terms,
//!   whose Jacobians are the rotation's times `s^k` (turned into the current
//!   camera), on the finest [`INTRA_LEVELS`] levels at a fast pace (all terms on the finest,
//!   all but `xi` on the next, `phi` on the coarser ones,
//!   [`Tracker::level_terms`]);
//! * alignment sees only differences of readout motion between a frame and
//!   its template: the absolute value is pinned by time ([`Gauge`]);
//! * fast motion estimates `phi, psi, chi`, and `xi` where the path bends
//!   enough to need it ([`QUARTIC_MIN_PX`]); slow motion estimates `phi`
//!   only, under a prior ([`PACE_SWITCH`]) that
//!   grows where the readout motion is too small to see
//!   ([`OBSERVABLE_READOUT_PX`]); there templates are rectified with the
//!   motion the rate predicts, so what the estimate absorbs (looming) cannot
//!   add up template after template.

mod irls;
mod residuals;

use crate::camera::CameraModel;
use crate::error::{check_range, AmcError};
use crate::image::GrayImage;
use crate::lanes;
use crate::pyramid::Pyramid;
use crate::shutter::RowTime;
use crate::shutter::{IntraFrame, INTRA_TERMS};
use crate::so3::{self, Rot, Tangent};
use irls::{irls_terms, outer_products, IrlsTerms, CHUNK};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use residuals::{residuals, sample_clamped};
use serde::{Deserialize, Serialize};

/// Parameters of the rotation tracker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerParams {
    /// Template reset period, in frames (`N_track`; paper: 5). Range 1..=1000.
    pub n_track: usize,
    /// Maximum number of pyramid levels (1 = single scale). Levels stop before a
    /// side would drop under 12 px. Range 1..=8.
    pub pyramid_levels: usize,
    /// Maximum number of template pixels per pyramid level. Range 64..=1_000_000.
    pub max_points: usize,
    /// Huber threshold on the intensity residual, in intensity units
    /// (intensities are in `[0, 1]`; 0.04 ~ 10/255). Range 0.001..=1.
    pub huber_delta: f64,
    /// Maximum Gauss-Newton iterations per pyramid level. Range 1..=200.
    pub max_iterations: usize,
    /// Convergence threshold: stop a level when the step moves pixels of that
    /// level by less than this, in pixels. Range 1e-5..=1.
    pub convergence_px: f64,
    /// Try a constant angular-velocity prediction as a warm start.
    pub predict: bool,
    /// Detect and ignore camera-fixed image regions (dashboards, overlays).
    /// Off by default: on cc9 (dashboard in view) it changed the gyro agreement
    /// by under 0.001 deg, so it is opt-in until footage shows a benefit.
    pub reject_static: bool,
}

impl Default for TrackerParams {
    fn default() -> Self {
        Self {
            n_track: 5,
            pyramid_levels: 4,
            max_points: 3000,
            huber_delta: 0.04,
            max_iterations: 30,
            convergence_px: 0.002,
            predict: true,
            reject_static: false,
        }
    }
}

impl TrackerParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<(), AmcError> {
        if !(1..=1000).contains(&self.n_track) {
            return Err(AmcError::invalid(
                "n_track",
                self.n_track,
                "1..=1000 frames",
            ));
        }
        if !(1..=8).contains(&self.pyramid_levels) {
            return Err(AmcError::invalid(
                "pyramid_levels",
                self.pyramid_levels,
                "1..=8",
            ));
        }
        if !(64..=1_000_000).contains(&self.max_points) {
            return Err(AmcError::invalid(
                "max_points",
                self.max_points,
                "64..=1000000",
            ));
        }
        check_range(
            "huber_delta",
            self.huber_delta,
            0.001,
            1.0,
            "0.001..=1 (intensity units)",
        )?;
        if !(1..=200).contains(&self.max_iterations) {
            return Err(AmcError::invalid(
                "max_iterations",
                self.max_iterations,
                "1..=200",
            ));
        }
        check_range(
            "convergence_px",
            self.convergence_px,
            1e-5,
            1.0,
            "0.00001..=1 pixels",
        )?;
        Ok(())
    }
}

/// Gradient magnitude (per pixel, intensity units) under which a pixel carries
/// no usable alignment information: ~0.5/255, the 8-bit quantisation step.
const MIN_GRADIENT: f32 = 0.5 / 255.0;
/// Line-search halvings before a level gives up (2^-8 of a step is negligible).
const MAX_BACKTRACK: usize = 8;
/// A frame is suspect when its RMS residual exceeds this multiple of the typical one.
const SUSPECT_RATIO: f32 = 2.5;
/// ...and this absolute floor (intensity units): noise-free clips have tiny residuals.
const SUSPECT_FLOOR: f32 = 0.02;
/// Recovery grid: offsets `-R..=R` steps on each of the pan and tilt axes.
const RECOVERY_RADIUS: i32 = 3;
/// Recovery grid step, in pixels of the coarsest level (inside its basin).
const RECOVERY_STEP_PX: f64 = 1.5;
/// Longest a template reset may be postponed while frames track badly.
const MAX_RESET_DELAY: usize = 10;
/// Convergence threshold of coarse levels relative to the finest level's.
const COARSE_TOLERANCE_FACTOR: f64 = 20.0;
/// Pyramid levels (finest first) on which a rolling shutter's readout motion
/// is estimated at a fast pace (every level of the default pyramid, see
/// [`Tracker::level_terms`]); coarser levels keep the last frame's.
const INTRA_LEVELS: usize = 4;
/// The same at a slow pace, where `phi` alone is estimated under a prior:
/// the two finest levels. On all four, cc9 (a phone's sway through 33 ms)
/// agreed with its gyro to 0.060 deg per frame instead of 0.057.
const SLOW_INTRA_LEVELS: usize = 2;
/// A rolling-shutter evaluation after a step that moved the points by more
/// than this (pixels of the level) sums its Gauss-Newton matrix afresh
/// instead of keeping the level's first ([`WarmStart`]): far from the optimum
/// the landing rows and the robust weights the matrix is made of move with
/// the pose. Measured (Gauss-Newton iterations per frame, always kept ->
/// this): 6.6 -> 6.1 on the tracking bench's clip, 11.0 -> 10.0 and 19.3 ->
/// 14.3 at 300 deg/s through 10 and 20 ms; refreshing after every step
/// saved no more iterations (6.0, 9.8, 14.4) and costs the full sums each
/// time.
const MATRIX_REFRESH_PX: f64 = 0.3;
/// Weight of the readout path's step in the convergence test: its terms
/// converge more slowly than the rotation (the bend and the S-shape are weakly
/// seen), and a move of the rows by `convergence_px / INTRA_TOLERANCE_SCALE`
/// is still far below what the estimate can resolve. Measured against 0.25
/// (tracking bench clip and the 300 deg/s pinhole ground truth): Gauss-Newton
/// iterations per frame 5.6 -> 5.0, 9.6 -> 8.8 and 13.0 -> 12.0, the eight
/// ground-truth clips' median per-frame errors within -2% to +4%; at 0.05
/// the 300 deg/s clip through 10 ms lost 9%.
const INTRA_TOLERANCE_SCALE: f64 = 0.1;
/// Least typical fourth-order bend of the readout path (finest-level pixels,
/// at the readout's ends, see [`Tracker::quartic_bend_px`]) at which its
/// fourth term `xi` is estimated. Measured on 12-20 Hz shake at 60 frames/s
/// (median per-frame error, ratio to a global shutter's): 100 deg/s through
/// 20 ms, cubic 3.5x, quartic 1.75x; 300 deg/s through 20 ms, 14x and 3.2-4.3x;
/// through 10 ms the cubic is better (1.56x and 2.25x against 1.70x and 2.5x:
/// the extra terms cost precision where there is nothing for them to fit).
const QUARTIC_MIN_PX: f64 = 0.05;
/// Fewer valid template pixels than this share means the frame is lost at that level.
const MIN_VALID_SHARE: f32 = 0.15;
/// A pixel votes on being camera-fixed only if the rotation moved it this far
/// (pixels, finest level): below this "fixed" and "rotating" look alike.
pub const STATIC_MIN_DISPLACEMENT_PX: f32 = 0.3;
/// Residuals below this (intensity units, ~1.5/255) are noise, not evidence.
const STATIC_NOISE: f32 = 1.5 / 255.0;
/// Weight of one frame's vote in the per-location moving average.
const STATIC_VOTE_GAIN: f32 = 0.25;
/// Average vote above which a location is treated as camera-fixed.
pub const STATIC_THRESHOLD: f32 = 0.3;

/// Pinhole intrinsics at one pyramid level, in `f32` for the hot loop.
#[derive(Clone, Copy, Debug)]
struct Intrinsics {
    fx: f32,
    fy: f32,
    skew: f32,
    cx: f32,
    cy: f32,
}

impl Intrinsics {
    fn from_camera(cam: &CameraModel) -> Self {
        Self {
            fx: cam.fx as f32,
            fy: cam.fy as f32,
            skew: cam.skew as f32,
            cx: cam.cx as f32,
            cy: cam.cy as f32,
        }
    }
    /// The same camera after a 2x2 box halving (pixel centre `u' = (u - 0.5) / 2`).
    fn halved(self) -> Self {
        Self {
            fx: self.fx * 0.5,
            fy: self.fy * 0.5,
            skew: self.skew * 0.5,
            cx: (self.cx - 0.5) * 0.5,
            cy: (self.cy - 0.5) * 0.5,
        }
    }

    /// The pixel ray `(x, y, z)` projects to; a ray behind the camera gets an
    /// out-of-image coordinate (branch-free, so the loops calling it vectorize).
    #[inline(always)]
    fn project(&self, x: f32, y: f32, z: f32) -> (f32, f32) {
        let iz = if z > 1e-6 { 1.0 / z } else { -1e9 };
        let (xn, yn) = (x * iz, y * iz);
        (
            self.fx * xn + self.skew * yn + self.cx,
            self.fy * yn + self.cy,
        )
    }

    /// The normalized ray `(x, y)` (at `z = 1`) through pixel `(u, v)`.
    fn ray(&self, u: f32, v: f32) -> (f32, f32) {
        let y = (v - self.cy) / self.fy;
        ((u - self.cx - self.skew * y) / self.fx, y)
    }
}

/// Precomputed template data of one pyramid level (structure of arrays).
#[derive(Clone, Debug, Default)]
struct LevelTemplate {
    k: Option<Intrinsics>,
    /// Normalized ray coordinates `(x, y)` of each selected template pixel.
    xs: Vec<f32>,
    ys: Vec<f32>,
    /// Rolling shutter: `xs`, `ys` and these are the ray rectified into the
    /// template's mid-readout camera (empty with a global shutter).
    zs: Vec<f32>,
    /// Template intensity.
    tv: Vec<f32>,
    /// Steepest-descent images, one per rotation axis (an array per axis, so
    /// that the loops over points load them as vectors).
    sd: [Vec<f32>; 3],
    /// Pixel index `v * width + u` in the level image.
    loc: Vec<u32>,
    /// Width of the level image, pixels.
    width: usize,
}

/// Sums of one pass over a level's template pixels.
#[derive(Clone, Copy, Debug, Default)]
struct Eval {
    /// Sum of the robust loss.
    loss: f64,
    /// Sum of squared residuals.
    sq: f64,
    n: u32,
    g: [f64; 3],
    /// Upper triangle of H: xx, xy, xz, yy, yz, zz.
    h: [f64; 6],
    /// Rolling shutter: `sum w s^k SD SD^T` for `k = 1..=2N` (upper
    /// triangles) and `sum w s^k SD e` for `k = 1..=N` (`N` the terms of the
    /// readout path), `s` the readout fraction of the row each point landed on
    /// (zero with a global shutter).
    hs: [[f64; 6]; 2 * INTRA_TERMS],
    gs: [[f64; 3]; INTRA_TERMS],
}

/// A frame's pose relative to the template: the mid-readout rotation
/// `R_{k,j}` and the motion during the readout.
#[derive(Clone, Copy, Debug)]
struct Pose {
    r: Rot,
    intra: IntraFrame,
}

/// One Gauss-Newton step: the rotation's (inverse compositional) and the
/// intra-frame motion's (additive; zero when it is not estimated).
#[derive(Clone, Copy, Debug)]
struct Step {
    delta: Tangent,
    /// Steps of the readout path's terms (`phi, psi, chi`).
    dterms: [Tangent; INTRA_TERMS],
}

impl Step {
    /// The largest angle the step moves a ray by (term `k` acts at most
    /// `2^-(k+1)` at `s = 1/2`).
    fn angle(&self) -> f64 {
        let intra: f64 = (self.dterms.iter())
            .enumerate()
            .map(|(k, d)| d.norm() * 0.5f64.powi(k as i32 + 1))
            .sum();
        self.delta.norm().max(intra * INTRA_TOLERANCE_SCALE)
    }

    /// `pose` moved by `scale` times this step.
    fn apply(&self, pose: &Pose, scale: f64) -> Pose {
        let mut terms = pose.intra.terms();
        for (t, d) in terms.iter_mut().zip(&self.dterms) {
            *t += d * scale;
        }
        Pose {
            r: so3::exp(&(self.delta * scale)) * pose.r,
            intra: IntraFrame::from_terms(terms),
        }
    }
}

impl Eval {
    /// Adds a chunk's robust loss, squared residual and valid count
    /// ([`IrlsTerms::sums`]).
    fn add_chunk_sums(&mut self, (loss, sq, n): (f64, f64, u32)) {
        self.loss += loss;
        self.sq += sq;
        self.n += n;
    }

    fn mean_loss(&self) -> f64 {
        if self.n == 0 {
            f64::INFINITY
        } else {
            self.loss / self.n as f64
        }
    }

    /// Solves the 3x3 Gauss-Newton system; `None` when it is degenerate.
    fn step(&self) -> Option<Tangent> {
        let h = &self.h;
        let m = Matrix3::new(h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5]);
        // A whisper of Levenberg damping keeps textureless axes from exploding.
        let damped = m + Matrix3::identity() * (1e-9 * m.trace() + 1e-18);
        let d = damped
            .cholesky()?
            .solve(&Vector3::new(self.g[0], self.g[1], self.g[2]));
        d.iter().all(|v| v.is_finite()).then_some(d)
    }

    /// The step of `pose`'s parameters: the rotation only, or with the
    /// readout path's terms (`intra`).
    ///
    /// With `P = R_{k,j}^T`, the residual's Jacobian at a point that landed
    /// on readout fraction `s` is `[SD, s P SD, s^2 P SD, s^3 P SD]`: moving
    /// term `k` by `d` turns the ray by `s^k d` in the current camera, which
    /// is the template-side rotation `s^k R d` (to first order), so with
    /// `Sk = sum w s^k SD SD^T` and `Gk = sum w s^k SD e`
    /// ```text
    /// H_ab = P_a S_(a+b) P_b^T,    g_a = P_a G_a      (P_0 = I, P_a = P)
    /// ```
    fn pose_step(
        &self,
        pose: &Pose,
        intra: bool,
        terms: usize,
        prior: Option<&ReadoutPrior>,
    ) -> Option<Step> {
        if !intra {
            return self.step().map(|delta| Step {
                delta,
                dterms: [Tangent::zeros(); INTRA_TERMS],
            });
        }
        const N: usize = 3 * (INTRA_TERMS + 1);
        let sym = |h: &[f64; 6]| Matrix3::new(h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5]);
        let p = *pose.r.matrix();
        let side = |a: usize| if a == 0 { Matrix3::identity() } else { p };
        let sk = |k: usize| {
            if k == 0 {
                sym(&self.h)
            } else {
                sym(&self.hs[k - 1])
            }
        };
        let gk = |k: usize| Vector3::from(if k == 0 { self.g } else { self.gs[k - 1] });
        let mut h = SMatrix::<f64, N, N>::zeros();
        let mut g = SVector::<f64, N>::zeros();
        for a in 0..=INTRA_TERMS {
            for b in 0..=INTRA_TERMS {
                let m = side(a) * sk(a + b) * side(b).transpose();
                h.fixed_view_mut::<3, 3>(3 * a, 3 * b).copy_from(&m);
            }
            g.fixed_rows_mut::<3>(3 * a).copy_from(&(side(a) * gk(a)));
        }
        // Levenberg damping, stronger on the readout terms than on the
        // rotation: they are weakly seen where texture is sparse.
        let damp = 1e-6 * h.trace() / N as f64 + 1e-18;
        for i in 0..N {
            h[(i, i)] += damp * if i < 3 { 1e-3 } else { 1.0 };
        }
        // Terms beyond `terms` are held (their rows pinned).
        let pin = 1e9 * h.trace();
        for i in 3 * (terms + 1)..N {
            h[(i, i)] += pin;
        }
        // The prior on the readout path (see [`ReadoutPrior`]).
        if let Some(prior) = prior {
            let dev = prior.deviation(&pose.intra);
            for k in 0..INTRA_TERMS {
                for a in 0..3 {
                    let i = 3 * (k + 1) + a;
                    h[(i, i)] += prior.weight;
                    g[i] -= prior.weight * dev[k][a];
                }
            }
        }
        let d = h.cholesky()?.solve(&g);
        if !d.iter().all(|v| v.is_finite()) {
            return None;
        }
        Some(Step {
            delta: d.fixed_rows::<3>(0).into_owned(),
            dterms: std::array::from_fn(|k| d.fixed_rows::<3>(3 * (k + 1)).into_owned()),
        })
    }
}

/// Quality of one frame's tracking.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackInfo {
    /// Gauss-Newton iterations over all levels.
    pub iterations: u32,
    /// RMS intensity residual at the finest level (intensity units).
    pub rms_residual: f32,
    /// Share of the finest level's template pixels that were valid.
    pub valid_fraction: f32,
    /// True when the template was replaced by this frame after tracking it.
    pub template_reset: bool,
    /// True when fewer than 15% of template pixels were valid (the estimate is a guess).
    pub lost: bool,
}

/// Streaming rotation tracker (one instance per clip).
pub struct Tracker {
    params: TrackerParams,
    base: Intrinsics,
    width: usize,
    height: usize,
    n_levels: usize,
    template: Vec<LevelTemplate>,
    /// Orientation of the template frame, `R_{0,k}`.
    r_0k: Rot,
    /// Current estimate relative to the template, `R_{k,j}`.
    r_kj: Rot,
    /// Last frame's orientation and body rate, for the velocity prediction.
    last: Option<(f64, Rot)>,
    rate: Tangent,
    frames_since_reset: usize,
    /// Scratch of [`build_level_template`]: its per-pixel scores.
    score: Vec<f32>,
    /// Per finest-level pixel: moving average of "camera-fixed" votes in [-1, 1].
    static_votes: Vec<f32>,
    /// Moving average of the RMS residual of well-tracked frames.
    typical_residual: Option<f32>,
    /// The last frame's motion during its readout.
    intra: IntraFrame,
    /// Rolling shutter: the readout fraction of each tracked pixel.
    rolling: Option<RowTime>,
    /// Rolling shutter through a distorted lens: that readout fraction at
    /// every pixel of each pyramid level, finest first
    /// ([`RowTime::level_table`]); empty when it is affine.
    row_tables: Vec<GrayImage>,
    /// Rolling shutter: the readout time, seconds.
    readout_s: f64,
    /// Rolling shutter: what the current template's readout motion is off by
    /// (its gauge, see [`Gauge`]); subtracted from the estimates made against it.
    gauge_tpl: IntraFrame,
    /// Rolling shutter: the running check of the gauge.
    gauge: Gauge,
    /// Rolling shutter: the mean of this frame's [`ReadoutPrior`].
    prior_mean: IntraFrame,
    /// Rolling shutter: moving averages of `w_j . w_(j-1)` and `|w_j|^2` for
    /// the pose-to-pose rates `w` (see [`PACE_SWITCH`]).
    pace: (f64, f64),
    /// The last time between two frames, seconds (0 until known).
    frame_dt: f64,
    /// Rolling shutter: the readout path the current template was rectified with.
    tpl_path: IntraFrame,
    /// Rolling shutter: whether the gauge has been checked once (see
    /// [`Tracker::settle_gauge`]).
    gauge_settled: bool,
    /// Rolling shutter: the sum of the corrections made to the gauge (see
    /// [`Tracker::gauge_corrections`]).
    gauge_corrections: IntraFrame,
    /// Rolling shutter: the start of a level's evaluations after its first
    /// (buffers reused from frame to frame).
    warm_start: WarmStart,
    /// The template before the current one (its buffers are reused by the
    /// next reset), while a handover to the current one is due.
    outgoing: Vec<LevelTemplate>,
    /// What else the frame after a reset is tracked against the outgoing
    /// template with ([`Tracker::hand_over`]); `None` when none is due.
    handover: Option<Handover>,
    /// The handover's [`WarmStart`] (the outgoing template's points).
    handover_warm: WarmStart,
    /// Rolling shutter: the frame being tracked is tried with the whole
    /// readout path free, before the pace is known ([`START_PATH_GAIN`]).
    start_path_free: bool,
}

/// The outgoing template's orientation and gauge, kept for one frame after a
/// reset ([`Tracker::hand_over`]).
#[derive(Clone, Copy, Debug)]
struct Handover {
    r_0k: Rot,
    gauge_tpl: IntraFrame,
}

/// What a rolling-shutter evaluation after the first at one level starts
/// from (a "warm" one; see [`Tracker::evaluate_rolling_with`]).
///
/// - Where each template point landed in the current frame at the level's
///   last evaluation, and how its fixed-point iteration converged there.
///   Between the evaluations of one level the pose moves by a Gauss-Newton
///   step, so a point's landing moves by about that step (a pixel at first,
///   hundredths of a pixel near the end). One fixed-point step from the last
///   landing, extrapolated with the first evaluation's contraction, then leaves
///   `~ |d kappa| / (1 - kappa)^2` of that move, where the first evaluation,
///   starting from the mid-readout projection (up to 8 px off at 300 deg/s
///   through 20 ms), needs two steps and the extrapolation: half the
///   projections.
/// - The level's first Gauss-Newton matrix (its moments up to `s^(2 terms)`,
///   two thirds of the evaluation's sums with a cubic path). The iteration's
///   fixed point is where the gradient vanishes whatever the matrix, and
///   near it the weights and rows the matrix is made of barely move; after a
///   step longer than [`MATRIX_REFRESH_PX`] the matrix is summed again.
///
/// Measured on the tracking bench's clip (100 deg/s, 15 ms): the same
/// evaluations per frame and the same accuracy on the ground-truth clips.
#[derive(Clone, Debug, Default)]
struct WarmStart {
    /// Whether the fields hold the level's first evaluation.
    valid: bool,
    /// Whether the next evaluation sums the matrix afresh (and keeps it).
    refresh: bool,
    /// Where each point landed at the level's last evaluation, pixels.
    u: Vec<f32>,
    v: Vec<f32>,
    /// Aitken's gain `kappa / (1 - kappa)` of each point's fixed-point
    /// iteration, measured by the level's first evaluation.
    gain: Vec<f32>,
    /// The level's first Gauss-Newton matrix ([`Eval::h`], [`Eval::hs`]).
    h: [f64; 6],
    hs: [[f64; 6]; 2 * INTRA_TERMS],
}

/// A Gaussian prior on a frame's readout path, in the template's gauge:
/// `phi` near the readout time times the last pose-to-pose rate, the higher
/// terms near zero. It costs `weight |theta - mean|^2 / 2` (intensity units
/// squared, the robust loss's), and `weight` is [`READOUT_PRIOR`] times the
/// information the level's points carry about one rotation axis: the data
/// outweigh it wherever they see the readout path (shake of 12-20 Hz filmed
/// through a 10-20 ms readout), and it holds the path where they barely do (a
/// hand's slow sway, a car's parallax and a scene that moves on its own).
#[derive(Clone, Copy, Debug)]
struct ReadoutPrior {
    mean: IntraFrame,
    weight: f64,
}

impl ReadoutPrior {
    /// `theta - mean`, term by term.
    fn deviation(&self, intra: &IntraFrame) -> [Tangent; INTRA_TERMS] {
        intra.plus(&self.mean, -1.0).terms()
    }

    /// `weight |theta - mean|^2 / 2`.
    fn energy(&self, intra: &IntraFrame) -> f64 {
        0.5 * self.weight
            * self
                .deviation(intra)
                .iter()
                .map(|d| d.norm_squared())
                .sum::<f64>()
    }
}

/// Strength of the [`ReadoutPrior`], relative to the data's information
/// about one rotation axis, where the readout motion is well observed (see
/// [`OBSERVABLE_READOUT_PX`]).
const READOUT_PRIOR: f64 = 1e-3;
/// Rotation across a readout (finest-level pixels, typical) from which the
/// data pin `phi` down against what else they fit. Below it the prior grows:
/// a drone flying forward slowly (karma.mp4, 5 deg/s, a 10 ms readout: 0.15
/// px) shows far more looming than readout motion, and looming's vertical half
/// is what `phi_x` does to the rows; estimated under the plain prior, `phi`
/// absorbed it and grew to 13 deg (148 with the higher terms free). cc9
/// (a phone in a car, 33 ms: ~0.9 px) keeps nearly the plain prior.
const OBSERVABLE_READOUT_PX: f64 = 2.0;
/// Least typical rotation across a readout (finest-level pixels) at which
/// the higher terms of the readout path are estimated (with a fast pace): a
/// path bending within a readout of less cannot be told from noise.
const MIN_FAST_READOUT_PX: f64 = 0.5;
/// The readout path's model follows the motion's pace, measured by the
/// lag-one autocorrelation of the pose-to-pose rates, `rho = <w_j . w_(j-1)> /
/// <|w_j|^2>` (moving averages), which is `cos(2 pi f dt)` for shake at `f` Hz.
/// Below this value the motion is fast (it turns within five frames:
/// flapping wings, a motor's vibration): the rate at the last frame predicts
/// the current one poorly, and the readout path bends and twists within a
/// readout, so `phi`, `psi` and `chi` are all estimated, freely. Above it the
/// motion is slow (a hand's sway, a car's ride): only `phi` is estimated,
/// under the [`ReadoutPrior`] (the last rate predicts it well), as the higher
/// terms would mostly fit parallax and moving objects. Measured: -0.27..-0.10
/// on 100-300 deg/s shake at 12-20 Hz and 60 frames/s; 0.55-0.71 on cc9 (a
/// phone in a car, 30 frames/s).
const PACE_SWITCH: f64 = 0.3;
/// Least typical second-order bend of the readout path (finest-level pixels,
/// at the readout's ends, see [`Tracker::quadratic_bend_px`]) at which the
/// motion counts as fast whatever its pace: large, slower shake (a legged
/// robot's gait, a runner's hand) turns less from frame to frame than
/// [`PACE_SWITCH`] asks, yet its path bends within a readout, which `phi`
/// alone cannot follow. Measured at 300 deg/s through 20 ms at 60 frames/s
/// (median per-frame error, ratio to a global shutter's): 6-10 Hz shake 140x
/// -> 2.4x, 3-5 Hz 55x -> 3.8x (bends of about 2 and 1 px); 12-20 Hz shake
/// was fast already and is unchanged. cc9 (a phone in a car, 33 ms: about
/// 0.1 px) and slow drone flight stay slow.
const MIN_BEND_PX: f64 = 0.5;
/// Weight of one frame in the moving averages of [`PACE_SWITCH`].
const PACE_GAIN: f64 = 0.05;
/// Until the pace is known (the first two frame pairs), a rolling-shutter
/// frame counts as slow, so only `phi` is estimated; it is tracked with the
/// whole path free as well, and that is kept where its residual is below this
/// share of the slow model's. At 300 deg/s through 20 ms the first frames'
/// paths bend by pixels and `phi` alone left residuals of 0.10-0.12 (0.01 once
/// tracking), two frames 2.8-3.7 deg off and 0.14 deg of orientation error
/// for good; the whole path leaves 0.02 and 0.044 deg (fisheye: 0.061 ->
/// 0.049 deg). On slow footage it gains little and is not kept: cc9 (a phone
/// in a car) 0.105 -> 0.092 and 0.126 -> 0.112 (kept, its gyro agreement
/// fell from 0.058 to 0.100 deg per frame, the higher terms fitting the
/// street's parallax).
const START_PATH_GAIN: f32 = 0.5;

/// The gauge of the readout motion.
///
/// Aligning frame `j` to template `k` sees the *difference* of their readout
/// motions: if both frames turn alike during their readouts, their rows are
/// displaced alike and the two images still differ by a pure rotation (to
/// first order). So the estimates inherit the template's error, template after
/// template, from the first frame's (unknown, taken as zero). What pins the
/// absolute value down is time: the rotation across a readout is the readout
/// time times the angular velocity, and summed over many frames the
/// velocities at the frames' mid-readouts and the pose-to-pose rates
/// `log(R_{j-1}^T R_j) / dt` agree (the latter sum to the net rotation; the
/// former sample the same motion), up to a bounded difference. So over a
/// block of `K` frames
/// ```text
/// c_phi = mean_j (phi_j - tau omega_j),     c_psi = mean_j psi_j,     c_chi = mean_j chi_j
/// ```
/// is the gauge error (to `tau |theta| / (K dt)`: 0.02 deg for 15 ms, 1.5 deg
/// of shake and a 1 s block), and is removed. Blocks start short
/// ([`GAUGE_FIRST_BLOCK`] frames) so the first frames' error goes early, and
/// double up to [`GAUGE_BLOCK`].
#[derive(Clone, Copy, Debug, Default)]
struct Gauge {
    /// Sums of `phi - tau omega` and of the higher terms.
    sums: [Tangent; INTRA_TERMS],
    count: usize,
    block: usize,
}

/// First block of the gauge check, frames.
const GAUGE_FIRST_BLOCK: usize = 8;
/// Longest block of the gauge check, frames.
const GAUGE_BLOCK: usize = 64;

impl Tracker {
    /// A tracker for frames of `camera` (a pinhole: undistort first).
    pub fn new(camera: &CameraModel, params: TrackerParams) -> Result<Self, AmcError> {
        params.validate()?;
        if !camera.is_pinhole() {
            return Err(AmcError::invalid(
                "tracking camera",
                "a distorted model",
                "a pinhole (the tracker runs on undistorted images)",
            ));
        }
        let n_levels = Pyramid::level_count(camera.width, camera.height, params.pyramid_levels);
        Ok(Self {
            start_path_free: false,
            base: Intrinsics::from_camera(camera),
            width: camera.width,
            height: camera.height,
            n_levels,
            template: vec![LevelTemplate::default(); n_levels],
            outgoing: vec![LevelTemplate::default(); n_levels],
            handover: None,
            handover_warm: WarmStart::default(),
            r_0k: Rot::identity(),
            r_kj: Rot::identity(),
            last: None,
            rate: Tangent::zeros(),
            frames_since_reset: 0,
            score: Vec::new(),
            static_votes: vec![0.0; camera.width * camera.height],
            typical_residual: None,
            intra: IntraFrame::ZERO,
            rolling: None,
            row_tables: Vec::new(),
            readout_s: 0.0,
            gauge_tpl: IntraFrame::ZERO,
            gauge: Gauge::default(),
            prior_mean: IntraFrame::ZERO,
            pace: (0.0, 0.0),
            frame_dt: 0.0,
            tpl_path: IntraFrame::ZERO,
            gauge_settled: false,
            gauge_corrections: IntraFrame::ZERO,
            warm_start: WarmStart::default(),
            params,
        })
    }

    /// Pyramid levels the caller must build for [`Tracker::track`].
    pub fn levels(&self) -> usize {
        self.n_levels
    }

    /// Size of the finest pyramid level the tracker expects.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Parameters in use.
    pub fn params(&self) -> &TrackerParams {
        &self.params
    }

    /// Turns the rolling-shutter model on: `rows` gives the readout fraction
    /// of each pixel of the tracked images. Each frame's motion during its
    /// readout is then estimated with its rotation ([`Tracker::intra`]).
    /// Set it before the first frame.
    pub fn set_rolling(&mut self, rows: RowTime, readout_s: f64) {
        // Each level's size as the pyramid halves it (see `pyramid::half_into`).
        let (mut w, mut h) = (self.width, self.height);
        self.row_tables.clear();
        for level in 0..self.n_levels {
            match rows.level_table(level, w, h) {
                Some(table) => self.row_tables.push(table),
                None => break,
            }
            (w, h) = (w / 2, h / 2);
        }
        self.rolling = Some(rows);
        self.readout_s = readout_s;
    }

    /// The last tracked frame's motion during its readout (zero with a
    /// global shutter).
    pub fn intra(&self) -> IntraFrame {
        self.intra
    }

    /// Whether the readout path's even terms (`psi`, and `xi`) are estimated,
    /// at the pace of the frames so far (a fast one, as `PACE_SWITCH` tells): only
    /// then is a frame's mid-readout pose less certain than a global
    /// shutter's (the centre of a fitted path trades off against its bend).
    pub fn estimates_bend(&self) -> bool {
        self.path_terms() >= 2
    }

    /// Whether the readout paths reported ([`Tracker::intra`]) are in the
    /// absolute gauge, checked against time at least once (see `Gauge`);
    /// before that, in the first frame's: each is the difference between
    /// the frame's path and the first frame's, whose own was unknown (zero).
    pub fn gauge_known(&self) -> bool {
        self.gauge_settled
    }

    /// The sum of the corrections made to the readout paths' gauge so far
    /// (the block check's and [`Tracker::regauge_template`]'s): each moved
    /// every later path reported by minus itself. A caller that shows the
    /// paths can ease the change in over a few frames instead of jumping
    /// ([`crate::shutter::GaugeEase`]).
    pub fn gauge_corrections(&self) -> IntraFrame {
        self.gauge_corrections
    }

    /// If the last frame became the template (rectified with its own path),
    /// rectifies it again with that path less `error`: the gauge error a
    /// trajectory through the recent frames found
    /// ([`crate::shutter::TrajectorySmoother::path_offset`]). From then on the
    /// corrections keep the gauge, so the block check restarts (`Gauge`).
    ///
    /// The block check averages `phi - tau omega` over 8-64 frames and is
    /// noisy and late: between its corrections the gauge wanders 0.04-0.13
    /// deg, and a template rectified with a path off by `c` biases every frame
    /// aligned to it by about `|a| |c| / 2` (see `Tracker::settle_gauge`).
    pub fn regauge_template(&mut self, error: &IntraFrame) {
        if self.frames_since_reset != 0 || self.tpl_path != self.intra || self.rolling.is_none() {
            return;
        }
        let path = self.intra.plus(error, -1.0);
        self.gauge_corrections = self.gauge_corrections.plus(error, 1.0);
        self.intra = path;
        self.rectify_template_again(path);
        self.gauge.sums = [Tangent::zeros(); INTRA_TERMS];
        self.gauge.count = 0;
    }

    /// Tracks the next frame (its pyramid and timestamp in seconds) and returns
    /// `R_{0,j}`, the rotation from this camera to the first frame's camera.
    pub fn track(&mut self, pyr: &Pyramid, t: f64) -> (Rot, TrackInfo) {
        let Some((t_prev, r_prev)) = self.last else {
            // First frame: it is the reference orientation and the first template.
            self.set_template(pyr);
            self.r_0k = Rot::identity();
            self.r_kj = Rot::identity();
            self.last = Some((t, Rot::identity()));
            let info = TrackInfo {
                template_reset: true,
                valid_fraction: 1.0,
                ..Default::default()
            };
            return (Rot::identity(), info);
        };
        let dt = t - t_prev;
        if dt.is_finite() && dt > 0.0 {
            self.frame_dt = dt;
        }

        // Warm-start candidates, as rotations relative to the template.
        // At most three candidates; a fixed array keeps `track` allocation-free.
        // With a rolling shutter each starts from the last frame's readout motion.
        // Terms that are not estimated (all but `phi` at a slow pace) are zero.
        let intra = self
            .intra
            .truncated(self.path_terms())
            .plus(&self.gauge_tpl, 1.0);
        self.prior_mean = self.path_of_rate(&self.rate).plus(&self.gauge_tpl, 1.0);
        let pose = |r| Pose { r, intra };
        let mut candidates = [
            pose(self.r_kj),
            pose(Rot::identity()),
            pose(Rot::identity()),
        ];
        let mut n_cand = 1;
        if self.params.predict && dt.is_finite() && dt > 0.0 {
            let predicted = r_prev * so3::exp(&(self.rate * dt));
            candidates[n_cand] = pose(self.r_0k.transpose() * predicted);
            n_cand += 1;
        }
        candidates[n_cand] = pose(Rot::identity());
        n_cand += 1;
        let coarsest = self.n_levels - 1;
        let mut start = candidates[0];
        let mut best = f64::INFINITY;
        for c in &candidates[..n_cand] {
            let e = self
                .evaluate(coarsest, &pyr.levels[coarsest], c, None)
                .mean_loss();
            if e < best {
                best = e;
                start = *c;
            }
        }

        let mut warm_start = std::mem::take(&mut self.warm_start);
        let (mut pose, mut info) = self.coarse_to_fine(pyr, start, dt, &mut warm_start);
        if self.rolling.is_some() && self.pace.1 == 0.0 {
            // The pace is not known yet (the first two frame pairs): the
            // whole path too, kept where the slow model leaves far more.
            self.start_path_free = true;
            let (free, free_info) = self.coarse_to_fine(pyr, start, dt, &mut warm_start);
            self.start_path_free = false;
            let spent = info.iterations + free_info.iterations;
            if free_info.rms_residual < START_PATH_GAIN * info.rms_residual {
                (pose, info) = (free, free_info);
            }
            info.iterations = spent;
        }
        if suspect(&info, self.typical_residual) {
            let (p2, info2) = self.recover(pyr, pose, dt, &mut warm_start);
            if info2.rms_residual < info.rms_residual {
                pose = p2;
                info = TrackInfo {
                    iterations: info.iterations + info2.iterations,
                    ..info2
                };
            }
        }
        self.warm_start = warm_start;
        let good = !suspect(&info, self.typical_residual) && !info.lost;
        if let Some(handover) = self.handover.take() {
            if good {
                info.iterations += self.hand_over(pyr, &pose, dt, handover);
            }
        }
        if good {
            let t = self.typical_residual.get_or_insert(info.rms_residual);
            *t += 0.1 * (info.rms_residual - *t);
        }
        self.r_kj = so3::renormalize(&pose.r);
        self.intra = pose.intra.plus(&self.gauge_tpl, -1.0);
        if self.params.reject_static && !info.lost {
            let r_kj = self.r_kj;
            self.vote_static(&pyr.levels[0], &r_kj);
        }
        let r_0j = so3::renormalize(&(self.r_0k * self.r_kj));
        if dt.is_finite() && dt > 0.0 {
            let rate = so3::body_rate(&r_prev, &r_0j, dt);
            if self.rolling.is_some() && good {
                let (c, p) = (rate.dot(&self.rate), rate.norm_squared());
                if self.rate == Tangent::zeros() {
                    // No earlier rate yet (the second frame).
                } else if self.pace.1 == 0.0 {
                    self.pace = (c, p);
                } else {
                    self.pace.0 += PACE_GAIN * (c - self.pace.0);
                    self.pace.1 += PACE_GAIN * (p - self.pace.1);
                }
            }
            self.rate = rate;
            if self.rolling.is_some() && good && self.check_gauge() {
                self.settle_gauge();
            }
        }
        self.last = Some((t, r_0j));

        self.frames_since_reset += 1;
        // With a rolling shutter the first template is held until the gauge
        // is first known (see [`Tracker::settle_gauge`]).
        let due = self.frames_since_reset >= self.params.n_track
            && (self.gauge_settled || !self.fast_motion());
        let overdue = self.frames_since_reset >= self.params.n_track + MAX_RESET_DELAY;
        if (due && good) || overdue {
            // The outgoing template stays for the next frame's handover; its
            // buffers are the ones the next reset after that fills.
            std::mem::swap(&mut self.template, &mut self.outgoing);
            self.handover = Some(Handover {
                r_0k: self.r_0k,
                gauge_tpl: self.gauge_tpl,
            });
            self.set_template(pyr);
            self.r_0k = r_0j;
            self.r_kj = Rot::identity();
            info.template_reset = true;
        }
        (r_0j, info)
    }

    /// Tracks the first frame after a reset against the outgoing template
    /// as well, starting from `pose` (its pose against the new one), and
    /// moves the new template's orientation so that both give the frame the
    /// same orientation; returns the Gauss-Newton iterations spent. Nothing
    /// moves when the outgoing template tracks the frame badly.
    ///
    /// A template's orientation is its frame's estimate, and every frame
    /// aligned to the template inherits that estimate's error, plus a bias of
    /// the template's own: with a rolling shutter the error of the path it
    /// was rectified with (rotations do not commute, so a path off by `c`
    /// turns every frame aligned to it by about `|a| |c| / 2`), with any
    /// shutter what its texture and sampling make of the rotation. Both are
    /// common to the template's frames and cancel between two of them, but
    /// at a reset they change at once: the first frame after it had twice
    /// the others' error (pinhole, 300 deg/s through 10 ms: 0.0042 against
    /// 0.0014-0.0017 deg), and over 4 s the steps added up to 0.14 deg
    /// (global shutter, 300 deg/s). Handed over, the new template continues
    /// the outgoing one's orientation, measured on a frame both see: that
    /// frame's error is the others' (0.0017 deg) and the drift after 4 s
    /// falls to 0.004 deg. It costs one more frame's tracking per template.
    fn hand_over(&mut self, pyr: &Pyramid, pose: &Pose, dt: f64, old: Handover) -> u32 {
        // The start: this frame's pose and path, taken to the outgoing
        // template's orientation and gauge.
        let start = Pose {
            r: old.r_0k.transpose() * self.r_0k * pose.r,
            intra: pose
                .intra
                .plus(&self.gauge_tpl, -1.0)
                .plus(&old.gauge_tpl, 1.0),
        };
        std::mem::swap(&mut self.template, &mut self.outgoing);
        let gauge_tpl = std::mem::replace(&mut self.gauge_tpl, old.gauge_tpl);
        let mut warm = std::mem::take(&mut self.handover_warm);
        let (seen, info) = self.coarse_to_fine(pyr, start, dt, &mut warm);
        self.handover_warm = warm;
        self.gauge_tpl = gauge_tpl;
        std::mem::swap(&mut self.template, &mut self.outgoing);
        if !info.lost && !suspect(&info, self.typical_residual) {
            let r_0j = old.r_0k * seen.r;
            self.r_0k = so3::renormalize(&(r_0j * pose.r.transpose()));
        }
        info.iterations
    }

    /// Whether the motion is fast for the readout path's model: it turns
    /// within a few frames ([`PACE_SWITCH`]), or its path bends visibly within
    /// a readout however slow its pace ([`MIN_BEND_PX`]); slow until two
    /// rates are known, but for the try with the whole path free then
    /// ([`START_PATH_GAIN`]).
    fn fast_motion(&self) -> bool {
        if self.start_path_free {
            return true;
        }
        self.readout_motion_px()
            .is_some_and(|px| px >= MIN_FAST_READOUT_PX)
            && (self.pace.0 < PACE_SWITCH * self.pace.1
                || self.quadratic_bend_px().is_some_and(|px| px >= MIN_BEND_PX))
    }

    /// How many terms of the readout path are estimated (on the levels that
    /// estimate it): none with a global shutter, `phi` alone with a slow
    /// pace, and with a fast one `phi, psi, chi`, and `xi` where the path
    /// bends enough ([`QUARTIC_MIN_PX`]).
    fn path_terms(&self) -> usize {
        if self.rolling.is_none() {
            0
        } else if !self.fast_motion() {
            1
        } else if self
            .quartic_bend_px()
            .is_some_and(|px| px >= QUARTIC_MIN_PX)
        {
            INTRA_TERMS
        } else {
            INTRA_TERMS - 1
        }
    }

    /// The pyramid levels (finest first) that estimate the readout path:
    /// [`INTRA_LEVELS`] at a fast pace, [`SLOW_INTRA_LEVELS`] at a slow one.
    fn intra_levels(&self) -> usize {
        if self.fast_motion() {
            INTRA_LEVELS
        } else {
            SLOW_INTRA_LEVELS
        }
    }

    /// The terms of the readout path estimated at pyramid `level`: all of
    /// [`Tracker::path_terms`] at the finest, all but the quartic `xi` on the
    /// next, `phi` alone on the coarser ones (down to
    /// [`Tracker::intra_levels`]; their rows barely see the bend and the
    /// S-shape).
    ///
    /// Each level hands the next its rotation, and the rotation absorbs what
    /// the level leaves out of the path: held at the last frame's (at 12-20
    /// Hz shake a poor guess) on the coarse levels and with only `phi` on the
    /// second, the finest level's first step moved the rotation by 0.2-0.3 px
    /// and the coarse levels crawled (Huber-weighted steps of 0.2 px, ten in a
    /// row, at 300 deg/s through 20 ms). Measured against `phi` on the two
    /// finest levels only, with [`MATRIX_REFRESH_PX`] (tracking bench clip,
    /// 100 deg/s through 15 ms, and the 300 deg/s pinhole ground truth):
    /// Gauss-Newton iterations per frame 8.5 -> 5.5, 15.2 -> 9.5 (10 ms) and
    /// 28.8 -> 12.9 (20 ms), with median per-frame errors 0.00318 -> 0.00303,
    /// 0.00296 -> 0.00279 and 0.00370 -> 0.00350 deg.
    fn level_terms(&self, level: usize) -> usize {
        match level {
            0 => self.path_terms(),
            1 => self.path_terms().min(INTRA_TERMS - 1),
            l if l < self.intra_levels() => self.path_terms().min(1),
            _ => 0,
        }
    }

    /// The typical fourth-order bend of the readout path at the readout's
    /// ends, in finest-level pixels; `None` until two rates are known.
    ///
    /// Shake at `f` Hz, `theta(t) = A sin(2 pi f t)`, has the rate amplitude
    /// `omega = 2 pi f A`, and its path's fourth Taylor term over a readout
    /// `tau` is `tau^4 theta'''' / 24`, of size `omega tau x^3 / 24` with
    /// `x = 2 pi f tau`; at `s = 1/2` that is `1/16` of it. `omega tau` in
    /// pixels is [`Tracker::readout_motion_px`], and `2 pi f dt` is the arc
    /// cosine of the rates' lag-one autocorrelation ([`PACE_SWITCH`]).
    fn quartic_bend_px(&self) -> Option<f64> {
        let (motion, x) = self.readout_phase()?;
        Some(motion * x.powi(3) / 384.0)
    }

    /// The typical second-order bend of the readout path at the readout's
    /// ends, in finest-level pixels (as [`Tracker::quartic_bend_px`]: the
    /// second Taylor term `tau^2 theta'' / 2` is of size `omega tau x / 2`,
    /// and `1/4` of it at `s = 1/2`); `None` until two rates are known.
    fn quadratic_bend_px(&self) -> Option<f64> {
        let (motion, x) = self.readout_phase()?;
        Some(motion * x / 8.0)
    }

    /// The typical rotation across a readout in finest-level pixels
    /// ([`Tracker::readout_motion_px`]) and the shake's phase across it,
    /// `x = 2 pi f tau` (from the rates' lag-one autocorrelation, see
    /// [`PACE_SWITCH`]); `None` until two rates are known.
    fn readout_phase(&self) -> Option<(f64, f64)> {
        let motion = self.readout_motion_px()?;
        if !(self.frame_dt > 0.0) {
            return None;
        }
        let rho = (self.pace.0 / self.pace.1).clamp(-1.0, 1.0);
        Some((motion, rho.acos() * self.readout_s / self.frame_dt))
    }

    /// The typical rotation across a readout, in finest-level pixels: the
    /// RMS pose-to-pose rate (the moving average of [`PACE_SWITCH`]) times the
    /// readout time times the focal length; `None` until two rates are known.
    fn readout_motion_px(&self) -> Option<f64> {
        (self.pace.1 > 0.0)
            .then(|| self.pace.1.sqrt() * self.readout_s * self.base.fx.max(self.base.fy) as f64)
    }

    /// Whether the readout motion is known to be too small to be observed
    /// (see [`OBSERVABLE_READOUT_PX`]).
    fn readout_unobservable(&self) -> bool {
        self.readout_motion_px()
            .is_some_and(|px| px < OBSERVABLE_READOUT_PX)
    }

    /// The weight of the [`ReadoutPrior`] per unit of the data's information:
    /// [`READOUT_PRIOR`] where the readout motion spans
    /// [`OBSERVABLE_READOUT_PX`] or more (or is not known yet), growing as the
    /// square of the shortfall below it (the data's pull on `phi` shrinks with
    /// the motion it has to see, while what else it fits, looming and
    /// parallax, does not).
    fn prior_strength(&self) -> f64 {
        let seen = self
            .readout_motion_px()
            .map_or(1.0, |px| px / OBSERVABLE_READOUT_PX);
        READOUT_PRIOR / seen.clamp(1e-2, 1.0).powi(2)
    }

    /// Adds the last frame to the gauge check; at the end of a block, removes
    /// the gauge error from this frame's readout motion and from every later
    /// estimate against the current template (see [`Gauge`]) and returns true.
    fn check_gauge(&mut self) -> bool {
        let g = &mut self.gauge;
        let mut terms = self.intra.terms();
        terms[0] -= self.rate * self.readout_s;
        for (sum, t) in g.sums.iter_mut().zip(terms) {
            *sum += t;
        }
        g.count += 1;
        if g.count < g.block.max(GAUGE_FIRST_BLOCK) {
            return false;
        }
        let c = IntraFrame::from_terms(g.sums.map(|sum| sum / g.count as f64));
        g.block = (g.count * 2).min(GAUGE_BLOCK);
        g.sums = [Tangent::zeros(); INTRA_TERMS];
        g.count = 0;
        self.intra = self.intra.plus(&c, -1.0);
        self.gauge_tpl = self.gauge_tpl.plus(&c, 1.0);
        self.gauge_corrections = self.gauge_corrections.plus(&c, 1.0);
        true
    }

    /// After a correction of the gauge at a fast pace, rectifies the current
    /// template again with its own readout path as now known, instead of the
    /// one it was given (zero for the first frame's, which is held until the
    /// first correction).
    ///
    /// Only differences of readout motion are seen to first order (see
    /// [`Gauge`]), but the rotations do not commute: a template rectified with
    /// a path off by `c` biases the rotation of every frame aligned to it by
    /// about `|a| |c| / 2` (`a` the path; `exp(a - c) != exp(-c) exp(a)`).
    /// The first template's path is wholly unknown, and that bias passed down
    /// the chain of templates as a lasting orientation error: 0.07 deg (10
    /// ms) and 0.13 deg (20 ms) within the first half second of 300 deg/s
    /// shake through a fisheye, 3-5x the global shutter's drift over 4 s.
    fn settle_gauge(&mut self) {
        if !self.fast_motion() {
            // At a slow pace the readout path is small and held near the rate's
            // prediction (see [`ReadoutPrior`]): there is little to correct, and
            // holding a template longer only lets parallax in (cc9: 0.057 ->
            // 0.066 deg against its gyro).
            self.gauge_settled = true;
            return;
        }
        if !self.gauge_settled {
            // The first template is kept for `n_track` more frames, so that
            // the next one's pose comes from the corrected template.
            self.gauge_settled = true;
            self.frames_since_reset = 0;
        }
        // The template was rectified with `tpl_path`; its estimates since are
        // off by `gauge_tpl`, so its own path is `tpl_path - gauge_tpl`.
        let path = self.tpl_path.plus(&self.gauge_tpl, -1.0);
        self.gauge_tpl = IntraFrame::ZERO;
        self.rectify_template_again(path);
    }

    /// Rectifies the current template again (every level), with `path` as
    /// its own readout path from now on. No effect with a global shutter.
    fn rectify_template_again(&mut self, path: IntraFrame) {
        let Some(rows) = &self.rolling else { return };
        self.tpl_path = path;
        for (level, tpl) in self.template.iter_mut().enumerate() {
            rectify_template(tpl, rows, self.row_tables.get(level), level, &path);
        }
    }

    /// Runs all levels from `pose`, returning the estimate and its quality.
    fn coarse_to_fine(
        &self,
        pyr: &Pyramid,
        mut pose: Pose,
        dt: f64,
        warm_start: &mut WarmStart,
    ) -> (Pose, TrackInfo) {
        let mut info = TrackInfo::default();
        for level in (0..self.n_levels).rev() {
            if level + 1 == self.intra_levels().min(self.n_levels) {
                if let Some(intra) = self.seed_intra(&pose, dt) {
                    pose.intra = intra;
                }
            }
            let (p_new, final_eval, iters) =
                self.refine(level, &pyr.levels[level], pose, warm_start);
            pose = p_new;
            info.iterations += iters;
            if level == 0 {
                let n_tpl = self.template[0].xs.len().max(1) as f32;
                info.valid_fraction = final_eval.n as f32 / n_tpl;
                info.rms_residual = if final_eval.n > 0 {
                    (final_eval.sq / final_eval.n as f64).sqrt() as f32
                } else {
                    f32::NAN
                };
                info.lost = info.valid_fraction < MIN_VALID_SHARE;
            }
        }
        (pose, info)
    }

    /// A fresh start for the readout path before the first level that
    /// estimates it, under fast motion: `phi` from the rate between the last
    /// frame and this frame's rotation as the coarse levels found it, and no
    /// higher terms. At 12-20 Hz shake the last frame's path (the start
    /// otherwise) is a poor guess, since the rates' lag-one autocorrelation is
    /// negative there, while this rate is centred only half a frame earlier.
    /// Measured on the tracking bench's clip: 4.0 -> 2.5 Gauss-Newton
    /// iterations per frame on that level, 10.9 -> 9.4 on all levels, with the
    /// same accuracy. `None`: keep the start (global shutter, slow motion, the
    /// first frame pair).
    fn seed_intra(&self, pose: &Pose, dt: f64) -> Option<IntraFrame> {
        let (_, r_prev) = self.last?;
        if self.rolling.is_none() || !self.fast_motion() || !(dt.is_finite() && dt > 0.0) {
            return None;
        }
        let rate = so3::body_rate(&r_prev, &(self.r_0k * pose.r), dt);
        Some(self.path_of_rate(&rate).plus(&self.gauge_tpl, 1.0))
    }

    /// The readout path a constant body rate `rate` draws: `phi = rate tau`,
    /// no higher terms.
    fn path_of_rate(&self, rate: &Tangent) -> IntraFrame {
        IntraFrame {
            phi: rate * self.readout_s,
            ..IntraFrame::ZERO
        }
    }

    /// Recovery from a wrong minimum: scores a pan/tilt grid around `center` at
    /// the coarsest level and refines the best point at all levels.
    fn recover(
        &self,
        pyr: &Pyramid,
        center: Pose,
        dt: f64,
        warm_start: &mut WarmStart,
    ) -> (Pose, TrackInfo) {
        let coarsest = self.n_levels - 1;
        let img = &pyr.levels[coarsest];
        let f = self.template[coarsest].k.map_or(1.0, |k| k.fx.max(k.fy)) as f64;
        let step = RECOVERY_STEP_PX / f;
        let min_valid = ((self.template[coarsest].xs.len() as f32) * MIN_VALID_SHARE) as u32;
        let mut best = (f64::INFINITY, center);
        for i in -RECOVERY_RADIUS..=RECOVERY_RADIUS {
            for j in -RECOVERY_RADIUS..=RECOVERY_RADIUS {
                // Offsets about the template camera's y (pan) and x (tilt) axes.
                let cand = Pose {
                    r: so3::exp(&Tangent::new(j as f64 * step, i as f64 * step, 0.0)) * center.r,
                    intra: center.intra,
                };
                let e = self.evaluate(coarsest, img, &cand, None);
                if e.n > min_valid && e.mean_loss() < best.0 {
                    best = (e.mean_loss(), cand);
                }
            }
        }
        self.coarse_to_fine(pyr, best.1, dt, warm_start)
    }

    /// Updates the camera-fixed votes from the finest level at the final estimate.
    fn vote_static(&mut self, img: &GrayImage, r: &Rot) {
        let tpl = &self.template[0];
        let Some(k) = tpl.k else { return };
        let m = r.matrix().transpose().map(|v| v as f32);
        let w = img.width;
        if self.static_votes.len() != w * img.height {
            return;
        }
        for i in 0..tpl.xs.len() {
            let (x, y) = (tpl.xs[i], tpl.ys[i]);
            let zc = m[(2, 0)] * x + m[(2, 1)] * y + m[(2, 2)];
            if zc <= 1e-6 {
                continue;
            }
            let xn = (m[(0, 0)] * x + m[(0, 1)] * y + m[(0, 2)]) / zc;
            let yn = (m[(1, 0)] * x + m[(1, 1)] * y + m[(1, 2)]) / zc;
            let u = k.fx * xn + k.skew * yn + k.cx;
            let v = k.fy * yn + k.cy;
            let loc = tpl.loc[i] as usize;
            let (u0, v0) = ((loc % w) as f32, (loc / w) as f32);
            let disp = ((u - u0).powi(2) + (v - v0).powi(2)).sqrt();
            if disp < STATIC_MIN_DISPLACEMENT_PX {
                continue;
            }
            let (Some(at_rot), Some(&at_id)) = (img.sample(u, v), img.data.get(loc)) else {
                continue;
            };
            let (e_rot, e_id) = ((at_rot - tpl.tv[i]).abs(), (at_id - tpl.tv[i]).abs());
            if !(e_rot.is_finite() && e_id.is_finite()) {
                continue;
            }
            let vote = if e_rot > STATIC_NOISE && e_id < 0.5 * e_rot {
                1.0
            } else if e_id > STATIC_NOISE && e_rot < 0.5 * e_id {
                -1.0
            } else {
                continue;
            };
            let s = &mut self.static_votes[loc];
            *s += STATIC_VOTE_GAIN * (vote - *s);
        }
    }

    /// Iterates Gauss-Newton with backtracking at one level.
    ///
    /// A step shorter than the level's convergence threshold ends the level
    /// without being tried: near the optimum such steps are noise, and testing
    /// them (with halvings) would cost full passes for nothing. With a rolling
    /// shutter the readout motion is estimated on the finest
    /// [`Tracker::intra_levels`] levels (coarser ones have too few rows to
    /// see it).
    fn refine(
        &self,
        level: usize,
        img: &GrayImage,
        mut pose: Pose,
        warm_start: &mut WarmStart,
    ) -> (Pose, Eval, u32) {
        let tpl = &self.template[level];
        let min_valid = ((tpl.xs.len() as f32) * MIN_VALID_SHARE).max(8.0) as u32;
        let f_level = tpl.k.map_or(1.0, |k| k.fx.max(k.fy)) as f64;
        let intra = self.rolling.is_some() && level < self.intra_levels();
        let mut prior = None;
        // Coarse levels only need to land inside the next level's basin.
        let tol = self.params.convergence_px
            * if level == 0 {
                1.0
            } else {
                COARSE_TOLERANCE_FACTOR
            };
        warm_start.valid = false;
        let mut cur = self.evaluate(level, img, &pose, Some(&mut *warm_start));
        let fast = self.fast_motion();
        if intra && !fast {
            prior = Some(ReadoutPrior {
                mean: self.prior_mean,
                weight: self.prior_strength() * (cur.h[0] + cur.h[3] + cur.h[5]) / 3.0,
            });
        }
        let terms = self.level_terms(level);
        // The objective: mean robust loss, plus the prior's share.
        let objective = |e: &Eval, p: &Pose| {
            e.mean_loss()
                + prior
                    .as_ref()
                    .map_or(0.0, |q| q.energy(&p.intra) / e.n.max(1) as f64)
        };
        let mut cur_obj = objective(&cur, &pose);
        let mut iters = 0;
        for _ in 0..self.params.max_iterations {
            if cur.n < min_valid {
                break;
            }
            let Some(step) = cur.pose_step(&pose, intra, terms, prior.as_ref()) else {
                break;
            };
            let step_px = step.angle() * f_level;
            if step_px < tol {
                break;
            }
            iters += 1;
            let mut s = 1.0;
            let mut accepted = false;
            for _ in 0..MAX_BACKTRACK {
                let cand = step.apply(&pose, s);
                warm_start.refresh = step_px * s > MATRIX_REFRESH_PX;
                let e = self.evaluate(level, img, &cand, Some(&mut *warm_start));
                let obj = objective(&e, &cand);
                if e.n >= min_valid && obj <= cur_obj {
                    pose = cand;
                    cur = e;
                    cur_obj = obj;
                    accepted = true;
                    break;
                }
                s *= 0.5;
                if step_px * s < tol {
                    break;
                }
            }
            if !accepted || step_px * s < tol {
                break;
            }
        }
        (pose, cur, iters)
    }

    /// One pass over a level's template pixels at `pose`, with the global-
    /// or the rolling-shutter model. `warm_start`: the level's Gauss-Newton
    /// iteration's (a rolling shutter's evaluations after the level's first
    /// start from it, see [`WarmStart`]); `None` for one-off evaluations.
    fn evaluate(
        &self,
        level: usize,
        img: &GrayImage,
        pose: &Pose,
        warm_start: Option<&mut WarmStart>,
    ) -> Eval {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2.
            return unsafe { self.evaluate_avx2(level, img, pose, warm_start) };
        }
        self.evaluate_body(level, img, pose, warm_start)
    }

    /// [`Self::evaluate_body`] compiled for AVX2: the same code, whose
    /// per-point loops the compiler vectorizes eight points wide instead of
    /// four. The sums are the same bits: [`lanes`] fixes their order.
    ///
    /// # Safety
    /// The CPU must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn evaluate_avx2(
        &self,
        level: usize,
        img: &GrayImage,
        pose: &Pose,
        warm_start: Option<&mut WarmStart>,
    ) -> Eval {
        self.evaluate_body(level, img, pose, warm_start)
    }

    /// [`Self::evaluate`] for whichever instruction set it is compiled.
    #[inline(always)]
    fn evaluate_body(
        &self,
        level: usize,
        img: &GrayImage,
        pose: &Pose,
        warm_start: Option<&mut WarmStart>,
    ) -> Eval {
        match &self.rolling {
            None => self.evaluate_global(level, img, &pose.r),
            Some(rows) => {
                let terms = self.level_terms(level);
                self.evaluate_rolling(level, img, pose, rows, terms, warm_start)
            }
        }
    }

    /// One pass over a level's template pixels at rotation `r = R_{k,j}`:
    /// robust loss, and the IRLS-weighted Gauss-Newton system.
    #[inline(always)]
    fn evaluate_global(&self, level: usize, img: &GrayImage, r: &Rot) -> Eval {
        let tpl = &self.template[level];
        let Some(k) = tpl.k else {
            return Eval::default();
        };
        let m = r.matrix().transpose().map(|v| v as f32);
        let (w, h) = (img.width, img.height);
        if w < 2 || h < 2 {
            return Eval::default();
        }
        let c = self.params.huber_delta as f32;
        let mut ev = Eval::default();
        let (mut pu, mut pv, mut pe) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
        let mut terms = IrlsTerms::default();
        let mut outer = [[0f32; CHUNK]; 6];
        // The matrix's and the gradient's lane accumulators, added up once
        // after the last chunk (see [`lanes::dot_into`]).
        let (mut h_lanes, mut g_lanes) = ([[0f32; lanes::LANES]; 6], [[0f32; lanes::LANES]; 3]);
        let m = [
            m[(0, 0)],
            m[(0, 1)],
            m[(0, 2)],
            m[(1, 0)],
            m[(1, 1)],
            m[(1, 2)],
            m[(2, 0)],
            m[(2, 1)],
            m[(2, 2)],
        ];
        let n_pts = tpl.xs.len();
        let mut lo = 0;
        while lo < n_pts {
            let hi = (lo + CHUNK).min(n_pts);
            // (`min`: tells the compiler `len <= CHUNK`, see the rolling pass.)
            let len = (hi - lo).min(CHUNK);
            let (xs, ys) = (&tpl.xs[lo..hi], &tpl.ys[lo..hi]);
            // Pass 1 (branch-free, vectorizes): project the rotated rays.
            // Rays behind the camera get an out-of-image coordinate.
            for q in 0..len {
                let (x, y) = (xs[q], ys[q]);
                (pu[q], pv[q]) = k.project(
                    m[0] * x + m[1] * y + m[2],
                    m[3] * x + m[4] * y + m[5],
                    m[6] * x + m[7] * y + m[8],
                );
            }
            // Pass 2 (gathers): bilinear residuals, NaN where invalid.
            residuals(img, &pu[..len], &pv[..len], &tpl.tv[lo..hi], &mut pe[..len]);
            // Pass 3: Huber loss and IRLS terms per point, summed in lanes.
            let sd = tpl.sd.each_ref().map(|a| &a[lo..hi]);
            irls_terms(&mut pe[..len], sd, c, &mut terms);
            outer_products(sd, &terms.wt, len, &mut outer);
            ev.add_chunk_sums(terms.sums(&pe[..len]));
            for (o, acc) in outer.iter().zip(&mut h_lanes) {
                lanes::sum_into(&o[..len], acc);
            }
            for (v, acc) in terms.we.iter().zip(&mut g_lanes) {
                lanes::sum_into(&v[..len], acc);
            }
            lo = hi;
        }
        ev.h = h_lanes.map(|a| lanes::lanes_total(&a));
        ev.g = g_lanes.map(|a| lanes::lanes_total(&a));
        ev
    }

    /// [`Tracker::evaluate_global`] through a rolling shutter: each template
    /// ray (rectified into the template's mid-readout camera) is projected
    /// into the current frame at the time of the row it lands on (fixed-point
    /// steps from the mid-readout guess, [`crate::shutter::project_rolling`]),
    /// and the sums carry that row's readout fraction for the intra-frame
    /// terms of [`Eval::pose_step`].
    ///
    /// The readout rotation `exp(-a)`, `a = s phi + ... + s^4 xi`, is applied to
    /// third order, `z + b x z + (b x (b x z)) / 2 + (b x (b x (b x z))) / 6`
    /// with `b = -a`: its error `|a|^4 / 24` is 3e-7 rad for a 6 deg turn
    /// across the readout (300 deg/s over 20 ms).
    #[inline(always)]
    fn evaluate_rolling(
        &self,
        level: usize,
        img: &GrayImage,
        pose: &Pose,
        rows: &RowTime,
        terms: usize,
        warm_start: Option<&mut WarmStart>,
    ) -> Eval {
        let table = self.row_tables.get(level);
        let row_times =
            |pu: &[f32], pv: &[f32], ps: &mut [f32]| row_times_into(rows, table, level, pu, pv, ps);
        self.evaluate_rolling_with(level, img, pose, terms, warm_start, row_times)
    }

    /// [`Tracker::evaluate_rolling`] with `row_times(pu, pv, ps)`, which
    /// writes the readout fraction of each level pixel `(pu, pv)` into `ps`
    /// (a chunk at a time, so that a table is sampled by the vector gathers
    /// and the passes around it stay vectorized). The intra-frame sums are
    /// accumulated for the first `n_terms` terms of the readout path (those
    /// the level estimates; none: 0).
    #[inline(always)]
    fn evaluate_rolling_with<T: Fn(&[f32], &[f32], &mut [f32])>(
        &self,
        level: usize,
        img: &GrayImage,
        pose: &Pose,
        n_terms: usize,
        mut warm_start: Option<&mut WarmStart>,
        row_times: T,
    ) -> Eval {
        let tpl = &self.template[level];
        let Some(k) = tpl.k else {
            return Eval::default();
        };
        let (w, h) = (img.width, img.height);
        if w < 2 || h < 2 || tpl.zs.len() != tpl.xs.len() {
            return Eval::default();
        }
        let mm = pose.r.matrix().transpose().map(|v| v as f32);
        let m: [f32; 9] = std::array::from_fn(|i| mm[(i / 3, i % 3)]);
        let path = pose
            .intra
            .terms()
            .map(|t| [t.x as f32, t.y as f32, t.z as f32]);
        let c = self.params.huber_delta as f32;
        let mut ev = Eval::default();
        let (mut pu, mut pv, mut pe, mut ps) =
            ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
        let (mut rx, mut ry, mut rz) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
        let (mut dv, mut gain) = ([0f32; CHUNK], [0f32; CHUNK]);
        let mut terms = IrlsTerms::default();
        let mut outer = [[0f32; CHUNK]; 6];
        let n_pts = tpl.xs.len();
        // Warm: start from the level's first evaluation (see [`WarmStart`]).
        let warm = match warm_start.as_deref_mut() {
            Some(l) if l.valid && l.u.len() == n_pts => true,
            Some(l) => {
                l.u.resize(n_pts, 0.0);
                l.v.resize(n_pts, 0.0);
                l.gain.resize(n_pts, 0.0);
                false
            }
            None => false,
        };
        let reuse = warm && !warm_start.as_deref().is_some_and(|l| l.refresh);
        // A one-off evaluation (a start candidate's, the recovery grid's)
        // is compared by its loss alone: the Gauss-Newton sums are skipped.
        let loss_only = warm_start.is_none();
        // The moments' lane accumulators: the matrix's `s^p` (p = 0..=2N) and
        // the gradient's (p = 0..=N).
        let mut h_lanes = [[[0f32; lanes::LANES]; 6]; 2 * INTRA_TERMS + 1];
        let mut g_lanes = [[[0f32; lanes::LANES]; 3]; INTRA_TERMS + 1];
        let mut lo = 0;
        while lo < n_pts {
            let hi = (lo + CHUNK).min(n_pts);
            // (`min`: tells the compiler `len <= CHUNK`, which lifts the
            // bounds checks out of the loops below and lets them vectorize.)
            let len = (hi - lo).min(CHUNK);
            // Pass 1 (branch-free loops over the chunk, which vectorize):
            // rotate the rays to the mid-readout pose.
            let (xs, ys, zs) = (&tpl.xs[lo..hi], &tpl.ys[lo..hi], &tpl.zs[lo..hi]);
            for q in 0..len {
                let (x, y, z) = (xs[q], ys[q], zs[q]);
                rx[q] = m[0] * x + m[1] * y + m[2] * z;
                ry[q] = m[3] * x + m[4] * y + m[5] * z;
                rz[q] = m[6] * x + m[7] * y + m[8] * z;
            }
            // Two fixed-point steps from the mid-readout guess, then Aitken's
            // extrapolation along the second.
            //
            // The step `y -> pi_y(exp(-a(s(y))) z)` moves the row by about `kappa = f
            // |a'(s)| / H` per row of change, so the iterates approach the landing point
            // geometrically, `p_n - p* ~ kappa^n (p_0 - p*)`, and from the last two moves
            // `kappa = dy_2 / dy_1` and `p* = p_2 + kappa / (1 - kappa) (p_2 - p_1)`
            // (both coordinates follow the row's time, so both extrapolate alike).
            // 300 deg/s through 20 ms (a 6 deg turn across the readout, 90 deg camera):
            // `kappa` ~0.1 and the guess up to 8 px off; two plain steps left 0.07 px at
            // the readout's ends, a bias that doubled the per-frame error (7.2x the
            // global shutter's against 3.2-3.6x with four steps or with the
            // extrapolation, which costs no projection).
            let land = |s: f32, q: usize| land_at(&k, &path, s, [rx[q], ry[q], rz[q]]);
            match warm_start.as_deref_mut() {
                Some(l) if warm => {
                    // One step from the last landing, extrapolated with its gain.
                    // (Sliced to `len`, not `lo..hi`: the compiler then sees
                    // every index in bounds and vectorizes the loop; with the
                    // check left in it ran a point at a time.)
                    let (lu, lv) = (&mut l.u[lo..][..len], &mut l.v[lo..][..len]);
                    let lg = &l.gain[lo..][..len];
                    row_times(lu, lv, &mut ps[..len]);
                    for q in 0..len {
                        let (u, v) = land(ps[q], q);
                        pu[q] = u + lg[q] * (u - lu[q]);
                        pv[q] = v + lg[q] * (v - lv[q]);
                        (lu[q], lv[q]) = (pu[q], pv[q]);
                    }
                    row_times(&pu[..len], &pv[..len], &mut ps[..len]);
                }
                cold => {
                    for q in 0..len {
                        (pu[q], pv[q]) = k.project(rx[q], ry[q], rz[q]);
                    }
                    row_times(&pu[..len], &pv[..len], &mut ps[..len]);
                    for q in 0..len {
                        let (u, v) = land(ps[q], q);
                        dv[q] = v - pv[q];
                        (pu[q], pv[q]) = (u, v);
                    }
                    row_times(&pu[..len], &pv[..len], &mut ps[..len]);
                    // A one-off evaluation (start candidates and the recovery
                    // grid, told apart on the coarsest level) stops after one
                    // step, which lands within a tenth of that level's pixel.
                    if !loss_only {
                        for q in 0..len {
                            let (u, v) = land(ps[q], q);
                            let (eu, ev) = (u - pu[q], v - pv[q]);
                            let ratio = if dv[q].abs() > 1e-4 {
                                (ev / dv[q]).clamp(-0.5, 0.5)
                            } else {
                                0.0
                            };
                            gain[q] = ratio / (1.0 - ratio);
                            pu[q] = u + gain[q] * eu;
                            pv[q] = v + gain[q] * ev;
                        }
                        row_times(&pu[..len], &pv[..len], &mut ps[..len]);
                        if let Some(l) = cold {
                            l.u[lo..hi].copy_from_slice(&pu[..len]);
                            l.v[lo..hi].copy_from_slice(&pv[..len]);
                            l.gain[lo..hi].copy_from_slice(&gain[..len]);
                        }
                    }
                }
            }
            // Pass 2 (gathers): bilinear residuals, NaN where invalid.
            residuals(img, &pu[..len], &pv[..len], &tpl.tv[lo..hi], &mut pe[..len]);
            // Pass 3: Huber loss and IRLS terms per point (a point whose row
            // time is not finite is invalid), then (estimating the readout
            // path) their moments in the rows' readout fractions, in lanes.
            for q in 0..len {
                pe[q] = if ps[q].is_finite() { pe[q] } else { f32::NAN };
            }
            let sd = tpl.sd.each_ref().map(|a| &a[lo..hi]);
            irls_terms(&mut pe[..len], sd, c, &mut terms);
            for q in 0..len {
                ps[q] = if terms.ok[q] > 0.0 { ps[q] } else { 0.0 };
            }
            ev.add_chunk_sums(terms.sums(&pe[..len]));
            if loss_only {
                lo = hi;
                continue;
            }
            if !reuse {
                outer_products(sd, &terms.wt, len, &mut outer);
            }
            // A warm evaluation sums the gradient's moments only (up to
            // `s^n_terms`); the matrix's (up to `s^(2 n_terms)`) are the level's
            // first evaluation's (see [`WarmStart`]).
            let moments = if reuse { n_terms } else { 2 * n_terms };
            // pw = s^p per point, p = 0..=moments (vectorized over points).
            let mut pw = [1f32; CHUNK];
            for p in 0..=moments {
                if p > 0 {
                    for q in 0..len {
                        pw[q] *= ps[q];
                    }
                }
                // Summed in lanes (as one serial f32 sum each, these 54 sums
                // per chunk were the tracker's hottest loop), the lanes added
                // up once after the last chunk.
                if !reuse {
                    for (o, acc) in outer.iter().zip(&mut h_lanes[p]) {
                        lanes::dot_into(&o[..len], &pw[..len], acc);
                    }
                }
                if p <= n_terms {
                    for (v, acc) in terms.we.iter().zip(&mut g_lanes[p]) {
                        lanes::dot_into(&v[..len], &pw[..len], acc);
                    }
                }
            }
            lo = hi;
        }
        for (p, acc) in h_lanes.iter().enumerate() {
            let hk = if p == 0 { &mut ev.h } else { &mut ev.hs[p - 1] };
            for (h, a) in hk.iter_mut().zip(acc) {
                *h = lanes::lanes_total(a);
            }
        }
        for (p, acc) in g_lanes.iter().enumerate() {
            let gk = if p == 0 { &mut ev.g } else { &mut ev.gs[p - 1] };
            for (g, a) in gk.iter_mut().zip(acc) {
                *g = lanes::lanes_total(a);
            }
        }
        if let Some(l) = warm_start {
            if reuse {
                (ev.h, ev.hs) = (l.h, l.hs);
            } else {
                (l.h, l.hs) = (ev.h, ev.hs);
            }
            l.valid = true;
        }
        ev
    }

    /// Makes `pyr` the template: selects pixels and precomputes steepest descent.
    fn set_template(&mut self, pyr: &Pyramid) {
        self.frames_since_reset = 0;
        // The new template is rectified with the gauge-corrected motion; with a
        // slow pace where the readout motion is too small to be observed (see
        // [`OBSERVABLE_READOUT_PX`]), with the motion the last rate predicts:
        // frames are aligned to the template and estimated relative to it, so
        // what the estimate absorbed besides the readout (looming, parallax)
        // would otherwise pass on to every later template and add up.
        self.gauge_tpl = IntraFrame::ZERO;
        let rectified = if self.fast_motion() || !self.readout_unobservable() {
            self.intra
        } else {
            self.path_of_rate(&self.rate)
        };
        self.tpl_path = rectified;
        let mut k = self.base;
        let votes = if self.params.reject_static {
            Some((&self.static_votes[..], self.width))
        } else {
            None
        };
        for level in 0..self.n_levels {
            let img = &pyr.levels[level];
            build_level_template(
                img,
                k,
                self.params.max_points,
                &mut self.score,
                votes.map(|(v, w)| (v, w, level)),
                &mut self.template[level],
            );
            if let Some(rows) = &self.rolling {
                rectify_template(
                    &mut self.template[level],
                    rows,
                    self.row_tables.get(level),
                    level,
                    &rectified,
                );
            }
            k = k.halved();
        }
    }
}

/// Whether a frame's final residual is far above the `typical` one (a wrong
/// local minimum, see [`SUSPECT_RATIO`]).
fn suspect(info: &TrackInfo, typical: Option<f32>) -> bool {
    let limit = typical.map_or(f32::INFINITY, |t| (SUSPECT_RATIO * t).max(SUSPECT_FLOOR));
    !(info.rms_residual <= limit)
}

/// Rolling shutter: turns each template ray into the template frame's
/// mid-readout camera, `y = exp(a(s)) x` for the readout fraction `s` of its
/// row (`a(s)` of the template frame's readout path), in `xs, ys, zs`.
/// The rays come from the points' pixels, so a template can be rectified
/// again with another path.
fn rectify_template(
    tpl: &mut LevelTemplate,
    rows: &RowTime,
    table: Option<&GrayImage>,
    level: usize,
    intra: &IntraFrame,
) {
    let Some(k) = tpl.k else {
        tpl.zs.clear();
        return;
    };
    let n = tpl.xs.len();
    tpl.zs.resize(n, 0.0);
    let w = tpl.width.max(1) as f64;
    let path = intra.terms().map(|t| [t.x as f32, t.y as f32, t.z as f32]);
    let (mut pu, mut pv, mut ps) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
    // In chunks, each pass a loop that vectorizes (a point at a time, with
    // an integer division for its pixel and the path in f64, this was as
    // costly as a tenth of the frames' tracking).
    for lo in (0..n).step_by(CHUNK) {
        let len = (n - lo).min(CHUNK);
        let loc = &tpl.loc[lo..][..len];
        for q in 0..len {
            // Exact: `loc < 2^32` and `w` are exact in f64, and the half
            // keeps the quotient off the integers.
            let v = ((loc[q] as f64 + 0.5) / w).floor();
            pv[q] = v as f32;
            pu[q] = (loc[q] as f64 - v * w) as f32;
        }
        row_times_into(rows, table, level, &pu[..len], &pv[..len], &mut ps[..len]);
        let (xs, ys, zs) = (
            &mut tpl.xs[lo..][..len],
            &mut tpl.ys[lo..][..len],
            &mut tpl.zs[lo..][..len],
        );
        for q in 0..len {
            let (x, y) = k.ray(pu[q], pv[q]);
            let s = ps[q];
            let ray = rotate_small(&path_at(&path, s), &[x, y, 1.0]);
            // A pixel whose ray leaves the sensor's lens (NaN `s`) keeps its ray.
            let ok = s.is_finite();
            xs[q] = if ok { ray[0] } else { x };
            ys[q] = if ok { ray[1] } else { y };
            zs[q] = if ok { ray[2] } else { 1.0 };
        }
    }
}

/// The readout fractions of pyramid level `level`'s pixels `(pu, pv)` into
/// `ps`: affine in the row, or from the level's table (`table`,
/// [`RowTime::level_table`]; a level without one, not reached, looks each
/// point up in `rows`).
#[inline(always)]
fn row_times_into(
    rows: &RowTime,
    table: Option<&GrayImage>,
    level: usize,
    pu: &[f32],
    pv: &[f32],
    ps: &mut [f32],
) {
    match (rows, table) {
        (RowTime::Affine { a, b }, _) => {
            let k = (1u32 << level) as f32;
            let (a, b) = (a * k, a * 0.5 * (k - 1.0) + b);
            for (s, v) in ps.iter_mut().zip(pv) {
                *s = a * v + b;
            }
        }
        (_, Some(table)) => sample_clamped(table, pu, pv, ps),
        (rows, None) => {
            for ((s, u), v) in ps.iter_mut().zip(pu).zip(pv) {
                *s = rows.at(level, *u, *v);
            }
        }
    }
}

/// Where ray `r` (in the frame's mid-readout camera) lands at readout fraction
/// `s` of the readout path `path` (`[phi, psi, chi, xi]`): `pi(K exp(-a(s)) r)`,
/// `a(s) = s phi + s^2 psi + s^3 chi + s^4 xi`, the rotation to third order
/// ([`rotate_small`]). Inlined into the loops over points, which vectorize.
#[inline(always)]
fn land_at(k: &Intrinsics, path: &[[f32; 3]; 4], s: f32, r: [f32; 3]) -> (f32, f32) {
    let b = path_at(path, s).map(|a| -a);
    let z = rotate_small(&b, &r);
    k.project(z[0], z[1], z[2])
}

/// `a(s) = s phi + s^2 psi + s^3 chi + s^4 xi` of the readout path `path`
/// (`[phi, psi, chi, xi]`), in Horner's form.
#[inline(always)]
fn path_at(path: &[[f32; 3]; 4], s: f32) -> [f32; 3] {
    let [phi, psi, chi, xi] = path;
    std::array::from_fn(|i| (phi[i] + (psi[i] + (chi[i] + xi[i] * s) * s) * s) * s)
}

/// `exp(b) z` for a small rotation vector `b`, to third order:
/// `z + b x z + (b x (b x z)) / 2 + (b x (b x (b x z))) / 6` (error `|b|^4 / 24`).
#[inline(always)]
fn rotate_small(b: &[f32; 3], z: &[f32; 3]) -> [f32; 3] {
    let cross = |a: &[f32; 3], c: &[f32; 3]| {
        [
            a[1] * c[2] - a[2] * c[1],
            a[2] * c[0] - a[0] * c[2],
            a[0] * c[1] - a[1] * c[0],
        ]
    };
    let b1 = cross(b, z);
    let b2 = cross(b, &b1);
    let b3 = cross(b, &b2);
    std::array::from_fn(|i| z[i] + b1[i] + 0.5 * b2[i] + b3[i] * (1.0 / 6.0))
}

/// True when level pixel `(u, v)` lies on a camera-fixed location (votes are
/// kept at the finest level; a level-`l` pixel's centre is at `2^l u + (2^l - 1)/2`).
fn is_static(votes: Option<(&[f32], usize, usize)>, u: usize, v: usize) -> bool {
    let Some((votes, w, level)) = votes else {
        return false;
    };
    let (fu, fv) = (
        (u << level) + ((1 << level) >> 1),
        (v << level) + ((1 << level) >> 1),
    );
    votes
        .get(fv * w + fu)
        .is_some_and(|&s| s > STATIC_THRESHOLD)
}

/// Fills `tpl` from `img`: per block, the pixel of largest gradient.
///
/// Two passes: a score per pixel (the squared central-difference gradient,
/// or -1 where the pixel cannot be chosen), in straight loops down the rows
/// that vectorize, then the first pixel of highest score in each block. (One
/// loop with the four tests chained per pixel ran scalar, and branched on
/// each: it cost as much as all the frame's Gauss-Newton evaluations.)
fn build_level_template(
    img: &GrayImage,
    k: Intrinsics,
    max_points: usize,
    score: &mut Vec<f32>,
    static_votes: Option<(&[f32], usize, usize)>,
    tpl: &mut LevelTemplate,
) {
    tpl.k = Some(k);
    tpl.width = img.width;
    tpl.loc.clear();
    tpl.xs.clear();
    tpl.ys.clear();
    tpl.zs.clear();
    tpl.tv.clear();
    for a in &mut tpl.sd {
        a.clear();
    }
    let (w, h) = (img.width, img.height);
    if w < 3 || h < 3 || img.data.len() < w * h {
        return;
    }
    let data = &img.data[..w * h];
    // Central-difference gradient (a per-pixel derivative) from a pixel's
    // left, right, upper and lower neighbours: one formula for the scores and
    // the chosen pixels' steepest-descent images.
    let gradient = |l: f32, r: f32, up: f32, down: f32| (0.5 * (r - l), 0.5 * (down - up));
    // Candidates: gradient above the quantisation step, on a valid pixel
    // (NaN compares false: a pixel next to an invalid one is never chosen),
    // and not camera-fixed; the border's scores are never read.
    let min_g2 = MIN_GRADIENT * MIN_GRADIENT;
    score.clear();
    score.resize(w * h, -1.0);
    for v in 1..h - 1 {
        let (up, row, down) = (
            &data[(v - 1) * w..v * w],
            &data[v * w..(v + 1) * w],
            &data[(v + 1) * w..(v + 2) * w],
        );
        let out = &mut score[v * w..(v + 1) * w];
        for u in 1..w - 1 {
            let (gx, gy) = gradient(row[u - 1], row[u + 1], up[u], down[u]);
            let g2 = gx * gx + gy * gy;
            out[u] = if g2 > min_g2 && row[u].is_finite() {
                g2
            } else {
                -1.0
            };
        }
        if static_votes.is_some() {
            for (u, s) in out.iter_mut().enumerate() {
                if *s > 0.0 && is_static(static_votes, u, v) {
                    *s = -1.0;
                }
            }
        }
    }
    let interior = (w - 2) * (h - 2);
    let block = ((interior as f64 / max_points as f64).sqrt().ceil() as usize).max(1);
    let mut v0 = 1;
    while v0 < h - 1 {
        let mut u0 = 1;
        while u0 < w - 1 {
            // The first pixel of the block (row by row) with the highest score.
            let (mut best, mut best_score) = (usize::MAX, -1.0f32);
            let u1 = (u0 + block).min(w - 1);
            for v in v0..(v0 + block).min(h - 1) {
                for (i, &s) in score[v * w + u0..v * w + u1].iter().enumerate() {
                    if s > best_score {
                        (best, best_score) = (v * w + u0 + i, s);
                    }
                }
            }
            if best != usize::MAX {
                let i = best;
                let (u, v) = ((i % w) as f32, (i / w) as f32);
                let (x, y) = k.ray(u, v);
                let jx = [-x * y, 1.0 + x * x, -y];
                let jy = [-(1.0 + y * y), x * y, x];
                let (gx, gy) = gradient(data[i - 1], data[i + 1], data[i - w], data[i + w]);
                let mut sd = [0f32; 3];
                for a in 0..3 {
                    let du = k.fx * jx[a] + k.skew * jy[a];
                    let dv = k.fy * jy[a];
                    sd[a] = gx * du + gy * dv;
                }
                tpl.xs.push(x);
                tpl.ys.push(y);
                tpl.tv.push(data[i]);
                for (a, v) in tpl.sd.iter_mut().zip(sd) {
                    a.push(v);
                }
                tpl.loc.push(i as u32);
            }
            u0 += block;
        }
        v0 += block;
    }
}
