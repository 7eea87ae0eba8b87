//! The streaming stabilizer: push a frame and its timestamp, get the stabilized
//! frame and its telemetry back.
//!
//! Per frame `j` (paper, Algorithm 1):
//! 1. track: `R_hat_{0,j} = R_hat_{0,k} R_hat_{k,j}` (template `k` reset every `N_track` frames);
//! 2. view: `R^view_{0,j}` from the SO(3) low-pass filter (or fixed, in saccade mode);
//! 3. frame: the zoom `z_j` that shows no border within the crop budget, the
//!    view pulled toward the camera where it would need more (`framing`);
//! 4. render: warp frames `i = j - N_avg + 1 ..= j` by `R_hat_{0,i}^T R^view_{0,j} Z_j^-1` and average.
//!
//! Memory is bounded by the averaging window (plus `lookahead` frames): the
//! frame ring, the accumulator and (saccade) the warped slots are allocated once
//! and reused; steady state allocates nothing per frame.
//!
//! One file per stage: `tracking.rs` (1), `view.rs` (2 and 3), `average.rs`
//! and `saccade.rs` (4); `rendering.rs` runs an output's steps in order and
//! reports its [`Telemetry`]. `push.rs` is the stream (frames in, outputs
//! out, pipelined or not), `setup.rs` builds a stabilizer and holds its
//! settings, `params.rs` its [`StabilizerParams`].

mod average;
mod buffered;
mod params;
mod push;
mod rendering;
mod saccade;
mod setup;
mod telemetry;
mod tracking;
mod view;

use crate::image::{Frame, PixelFormat};
use crate::render::AutoDeghost;
use crate::shutter::RollingProjector;
use crate::so3::Rot;
use buffered::Buffered;
use rendering::Rendering;
use std::collections::VecDeque;
use tracking::Tracking;

pub use params::StabilizerParams;
pub use push::GivenPose;
pub use setup::MAX_RENDER_SHARE;
pub use telemetry::Telemetry;

/// The streaming stabilizer (one per clip).
pub struct Stabilizer {
    params: StabilizerParams,
    width: usize,
    height: usize,
    format: Option<PixelFormat>,
    tracking: Tracking,
    rendering: Rendering,
    ring: VecDeque<Buffered>,
    /// Buffers of frames that left the ring, for reuse.
    spare: Vec<(Frame, RollingProjector)>,
    view_fwd: Rot,
    received: u64,
    last_t: Option<f64>,
    /// Render output `j` while tracking frame `j + 1 + lookahead` (on the
    /// caller's rayon pool with the `parallel` feature).
    pipelined: bool,
    /// `deghost=auto`: the clip's noise, measured as frames arrive.
    auto_deghost: Option<AutoDeghost>,
}
