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

mod eval;
mod gauge;
mod handover;
mod intrinsics;
mod irls;
mod landing;
mod pace;
mod params;
mod recover;
mod rectify;
mod residuals;
mod rolling;
mod shutter_prior;
mod solve;
mod step;
mod template;
#[cfg(test)]
mod tests;
mod track;
mod vote;

use crate::image::GrayImage;
use crate::shutter::{IntraFrame, RowTime};
use crate::so3::{Rot, Tangent};
use gauge::Gauge;
use handover::Handover;
use intrinsics::Intrinsics;
use rolling::WarmStart;
use template::LevelTemplate;

pub use params::{TrackInfo, TrackerParams};
pub use vote::{STATIC_MIN_DISPLACEMENT_PX, STATIC_THRESHOLD};

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
