//! Synthetic test clips for AMC: a flapping-wing shake trajectory and a renderer that
//! films an equirectangular panorama with any [`CameraModel`], including a
//! rolling shutter.
//!
//! # Shake trajectory
//!
//! Per axis `i in {x, y, z}` the shake angle is a sum of `N = 8` sinusoids
//! ```text
//! theta_i(t) = s * sum_k a_ik sin(2 pi f_ik t + phi_ik)
//! ```
//! with frequencies `f_ik` drawn inside the band `[lo, hi]` (one per equal
//! sub-band, jittered, so no two are nearly equal), phases `phi_ik` uniform in
//! `[0, 2 pi)` and relative amplitudes `a_ik` uniform in `[0.5, 1]`, all from a
//! SplitMix64 generator seeded with `seed` (deterministic on every platform).
//! With an optional constant yaw pan of rate `p` (rad/s) about the world y axis
//! the absolute orientation is
//! ```text
//! A(t) = exp(p t e_y) exp(theta(t))
//! ```
//! and the trajectory reported to callers is relative to the first frame:
//! `R_{0}(t) = A(0)^T A(t)`, so `R_{0}(0) = I` (it is `R_{0,j}` of the frame
//! exposed at `t`). Its body angular velocity (in the current camera's frame) is
//! ```text
//! omega(t) = J_r(theta) theta'(t) + exp(theta)^T (p e_y)
//! J_r(w) = I - (1 - cos|w|)/|w|^2 [w]x + (|w| - sin|w|)/|w|^3 [w]x^2
//! ```
//! The scale `s` is chosen so that the RMS of `|J_r(theta) theta'|` (the shake
//! part, pan excluded) over `t in [0, 10 s)` sampled at 2 kHz equals
//! `shake_dps`: start from the small-angle estimate and apply the fixed-point
//! update `s <- s * target / measured` three times (the map is nearly linear).
//!
//! # Rendering
//!
//! For every output pixel, `n x n` sub-pixel rays (offsets `(i + 0.5)/n - 0.5`)
//! are unprojected once by [`EquirectRenderer::new`]. A frame is rendered with
//! an orientation per row (rolling shutter: row `v` of a frame `H` rows high
//! is exposed at `t + readout * (v / H - 1/2)`, [`amc_core::shutter::row_fraction`],
//! so the frame's time `t` is its mid-readout time, the pose the telemetry
//! reports; the caller maps that row fraction to an orientation). For a
//! camera ray `d_cam`:
//! ```text
//! d = R_{0}(t_row) d_cam                      (world = camera 0)
//! lon = atan2(d.x, d.z),   lat = atan2(-d.y, sqrt(d.x^2 + d.z^2))   (y is down)
//! u = (lon / (2 pi) + 0.5) W - 0.5,   v = (0.5 - lat / pi) H - 0.5
//! ```
//! and the panorama is sampled bilinearly at `(u, v)` (wrapping horizontally,
//! clamped vertically). The pixel is the mean of its sub-samples; sub-rays the
//! camera cannot unproject contribute black. Because a panorama is usually much
//! finer than the camera, [`downsample_pano`] box-filters it first, by the
//! factor [`pano_downsample_factor`] picks from the camera's angular pixel size
//! at the centre: `floor((W / 2 pi) / fx)`, at least 1.
//!
//! Test data, not the algorithm: `amc-core` does not need it, so it lives
//! here, beside it (pure as the core: no I/O, no threads, builds for
//! `wasm32-unknown-unknown`). `rng.rs` is the generator, `shake.rs` the
//! trajectory, `panorama.rs` the panorama's box filter, `equirect.rs` the
//! renderer.

#![deny(missing_docs)]

mod equirect;
mod panorama;
mod rng;
mod shake;

pub use equirect::{render_equirect, EquirectRenderer};
pub use panorama::{downsample_pano, pano_downsample_factor};
pub use shake::{Shake, ShakeParams};
