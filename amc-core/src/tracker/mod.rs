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
mod state;
mod step;
mod template;
#[cfg(test)]
mod tests;
mod track;
mod vote;

pub use params::{TrackInfo, TrackerParams};
pub use state::Tracker;
pub use vote::{STATIC_MIN_DISPLACEMENT_PX, STATIC_THRESHOLD};
