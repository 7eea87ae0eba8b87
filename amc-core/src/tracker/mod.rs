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
//!
//! ## Files
//! * `track.rs`: the track loop (warm start, estimate, template reset);
//! * `params.rs`: [`TrackerParams`] and [`TrackInfo`];
//! * `template.rs`, `intrinsics.rs`: the template's pixels and their
//!   steepest-descent images, per pyramid level;
//! * `eval.rs`, `irls.rs`, `residuals.rs`: one pass over a level's pixels (the
//!   robust loss and the Gauss-Newton sums), global shutter;
//! * `rolling.rs`, `landing.rs`, `rectify.rs`: the same through a rolling shutter;
//! * `step.rs`: the Gauss-Newton step; `solve.rs`: its iteration, coarse to fine;
//! * `recover.rs`: recovery from a wrong minimum; `handover.rs`: template handover;
//! * `gauge.rs`, `shutter_prior.rs`, `pace.rs`: the readout path's gauge, its
//!   prior, and which of its terms are estimated;
//! * `vote.rs`: camera-fixed regions.

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
    /// Scratch of [`build_level_template`](template::build_level_template): its per-pixel scores.
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
    /// Rolling shutter: the mean of this frame's [`ReadoutPrior`](shutter_prior::ReadoutPrior).
    prior_mean: IntraFrame,
    /// Rolling shutter: moving averages of `w_j . w_(j-1)` and `|w_j|^2` for
    /// the pose-to-pose rates `w` (see [`PACE_SWITCH`](pace::PACE_SWITCH)).
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
    /// readout path free, before the pace is known ([`START_PATH_GAIN`](pace::START_PATH_GAIN)).
    start_path_free: bool,
}
