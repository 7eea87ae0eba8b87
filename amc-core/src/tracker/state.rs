//! What a [`Tracker`] carries from frame to frame: the tracker itself and the
//! state types its files share (the template's levels, the warm start of a
//! rolling-shutter level, the gauge check, a pending handover). Defined here,
//! apart from the files that work on them, so that no file of the tracker
//! imports one that imports it back.

use super::intrinsics::Intrinsics;
use super::params::TrackerParams;
use crate::image::GrayImage;
use crate::shutter::{IntraFrame, RowTime, INTRA_TERMS};
use crate::so3::{Rot, Tangent};

/// Streaming rotation tracker (one instance per clip).
pub struct Tracker {
    pub(super) params: TrackerParams,
    pub(super) base: Intrinsics,
    pub(super) width: usize,
    pub(super) height: usize,
    pub(super) n_levels: usize,
    pub(super) template: Vec<LevelTemplate>,
    /// Orientation of the template frame, `R_{0,k}`.
    pub(super) r_0k: Rot,
    /// Current estimate relative to the template, `R_{k,j}`.
    pub(super) r_kj: Rot,
    /// Last frame's orientation and body rate, for the velocity prediction.
    pub(super) last: Option<(f64, Rot)>,
    pub(super) rate: Tangent,
    pub(super) frames_since_reset: usize,
    /// Scratch of [`build_level_template`](super::template::build_level_template): its per-pixel scores.
    pub(super) score: Vec<f32>,
    /// Per finest-level pixel: moving average of "camera-fixed" votes in [-1, 1].
    pub(super) static_votes: Vec<f32>,
    /// Moving average of the RMS residual of well-tracked frames.
    pub(super) typical_residual: Option<f32>,
    /// The last frame's motion during its readout.
    pub(super) intra: IntraFrame,
    /// Rolling shutter: the readout fraction of each tracked pixel.
    pub(super) rolling: Option<RowTime>,
    /// Rolling shutter through a distorted lens: that readout fraction at
    /// every pixel of each pyramid level, finest first
    /// ([`RowTime::level_table`]); empty when it is affine.
    pub(super) row_tables: Vec<GrayImage>,
    /// Rolling shutter: the readout time, seconds.
    pub(super) readout_s: f64,
    /// Rolling shutter: what the current template's readout motion is off by
    /// (its gauge, see [`Gauge`]); subtracted from the estimates made against it.
    pub(super) gauge_tpl: IntraFrame,
    /// Rolling shutter: the running check of the gauge.
    pub(super) gauge: Gauge,
    /// Rolling shutter: the mean of this frame's [`ReadoutPrior`](super::shutter_prior::ReadoutPrior).
    pub(super) prior_mean: IntraFrame,
    /// Rolling shutter: moving averages of `w_j . w_(j-1)` and `|w_j|^2` for
    /// the pose-to-pose rates `w` (see [`PACE_SWITCH`](super::pace::PACE_SWITCH)).
    pub(super) pace: (f64, f64),
    /// The last time between two frames, seconds (0 until known).
    pub(super) frame_dt: f64,
    /// Rolling shutter: the readout path the current template was rectified with.
    pub(super) tpl_path: IntraFrame,
    /// Rolling shutter: whether the gauge has been checked once (see
    /// [`Tracker::settle_gauge`]).
    pub(super) gauge_settled: bool,
    /// Rolling shutter: the sum of the corrections made to the gauge (see
    /// [`Tracker::gauge_corrections`]).
    pub(super) gauge_corrections: IntraFrame,
    /// Rolling shutter: the start of a level's evaluations after its first
    /// (buffers reused from frame to frame).
    pub(super) warm_start: WarmStart,
    /// The template before the current one (its buffers are reused by the
    /// next reset), while a handover to the current one is due.
    pub(super) outgoing: Vec<LevelTemplate>,
    /// What else the frame after a reset is tracked against the outgoing
    /// template with ([`Tracker::hand_over`]); `None` when none is due.
    pub(super) handover: Option<Handover>,
    /// The handover's [`WarmStart`] (the outgoing template's points).
    pub(super) handover_warm: WarmStart,
    /// Rolling shutter: the frame being tracked is tried with the whole
    /// readout path free, before the pace is known ([`START_PATH_GAIN`](super::pace::START_PATH_GAIN)).
    pub(super) start_path_free: bool,
}

/// Precomputed template data of one pyramid level (structure of arrays).
#[derive(Clone, Debug, Default)]
pub(super) struct LevelTemplate {
    pub(super) k: Option<Intrinsics>,
    /// Normalized ray coordinates `(x, y)` of each selected template pixel.
    pub(super) xs: Vec<f32>,
    pub(super) ys: Vec<f32>,
    /// Rolling shutter: `xs`, `ys` and these are the ray rectified into the
    /// template's mid-readout camera (empty with a global shutter).
    pub(super) zs: Vec<f32>,
    /// Template intensity.
    pub(super) tv: Vec<f32>,
    /// Steepest-descent images, one per rotation axis (an array per axis, so
    /// that the loops over points load them as vectors).
    pub(super) sd: [Vec<f32>; 3],
    /// Pixel index `v * width + u` in the level image.
    pub(super) loc: Vec<u32>,
    /// Width of the level image, pixels.
    pub(super) width: usize,
}

/// What a rolling-shutter evaluation after the first at one level starts
/// from (a "warm" one; see [`Tracker::evaluate_rolling_with`]).
///
/// - Where each template point landed in the current frame at the level's
///   last evaluation, and how its fixed-point iteration converged there.
///   Between the evaluations of one level the pose moves by a Gauss-Newton
///   step, so a point's landing moves by about that step. One fixed-point
///   step from the last landing, extrapolated with the first evaluation's
///   contraction, then leaves `~ |d kappa| / (1 - kappa)^2` of that move,
///   where the first evaluation, starting from the mid-readout projection,
///   needs two steps and the extrapolation: half the projections.
/// - The level's first Gauss-Newton matrix (its moments up to `s^(2 terms)`,
///   two thirds of the evaluation's sums with a cubic path). The iteration's
///   fixed point is where the gradient vanishes whatever the matrix, and
///   near it the weights and rows the matrix is made of barely move; after a
///   step longer than [`MATRIX_REFRESH_PX`] the matrix is summed again.
///
/// The same evaluations per frame and the same accuracy (see
/// `docs/core-history.md#tracker-warm-start`).
#[derive(Clone, Debug, Default)]
pub(super) struct WarmStart {
    /// Whether the fields hold the level's first evaluation.
    pub(super) valid: bool,
    /// Whether the next evaluation sums the matrix afresh (and keeps it).
    pub(super) refresh: bool,
    /// Where each point landed at the level's last evaluation, pixels.
    pub(super) u: Vec<f32>,
    pub(super) v: Vec<f32>,
    /// Aitken's gain `kappa / (1 - kappa)` of each point's fixed-point
    /// iteration, measured by the level's first evaluation.
    pub(super) gain: Vec<f32>,
    /// The level's first Gauss-Newton matrix ([`Eval::h`](super::eval::Eval::h), [`Eval::hs`](super::eval::Eval::hs)).
    pub(super) h: [f64; 6],
    pub(super) hs: [[f64; 6]; 2 * INTRA_TERMS],
}

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
/// ([`GAUGE_FIRST_BLOCK`](super::gauge::GAUGE_FIRST_BLOCK) frames) so the first frames' error goes early, and
/// double up to [`GAUGE_BLOCK`](super::gauge::GAUGE_BLOCK).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Gauge {
    /// Sums of `phi - tau omega` and of the higher terms.
    pub(super) sums: [Tangent; INTRA_TERMS],
    pub(super) count: usize,
    pub(super) block: usize,
}

/// The outgoing template's orientation and gauge, kept for one frame after a
/// reset ([`Tracker::hand_over`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Handover {
    pub(super) r_0k: Rot,
    pub(super) gauge_tpl: IntraFrame,
}

/// A frame's pose relative to the template: the mid-readout rotation
/// `R_{k,j}` and the motion during the readout.
#[derive(Clone, Copy, Debug)]
pub(super) struct Pose {
    pub(super) r: Rot,
    pub(super) intra: IntraFrame,
}
