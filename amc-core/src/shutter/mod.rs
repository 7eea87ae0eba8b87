//! Rolling shutter: a camera model with time.
//!
//! A rolling-shutter sensor reads its rows out one after another. Row `y` of
//! frame `j` (sensor rows, `0..H`) is exposed at
//! ```text
//! t_j + tau s(y),        s(y) = y / H - 1/2
//! ```
//! (`tau` the readout time; `s` the row's readout fraction, `0` at the middle
//! row). The frame's pose `R_{0,j}` is its mid-readout pose, and within the
//! frame the orientation follows a quartic in `s` on SO(3):
//! ```text
//! R_{0,j}(s) = R_{0,j} exp(s phi_j + s^2 psi_j + s^3 chi_j + s^4 xi_j)
//! ```
//! `phi_j` (radians, camera-j frame) is the rotation across the readout
//! (`tau` times the angular velocity at mid-readout), `psi_j`, `chi_j` and
//! `xi_j` the next Taylor terms (`tau^2 / 2` times the angular acceleration,
//! `tau^3 / 6` times the jerk, `tau^4 / 24` times the snap). At 12-20 Hz
//! shake a readout can span 0.4 of a shake period: a constant velocity per
//! frame leaves a bend that biases the mid-readout pose, so the tracker
//! estimates the terms the motion needs (see `tracker/`), from the
//! intensities, per frame ([`IntraFrame`]); a quartic follows such shake to
//! well under the tracking error (see `docs/core-history.md#shutter-terms`).
//!
//! A ray seen at sensor row `y` is rotated by `exp(-a(s))`, `a(s) = s phi +
//! s^2 psi + s^3 chi + s^4 xi`, from
//! the mid-readout camera; which row it lands on depends on that rotation, so
//! projection is a fixed point, solved from the mid-readout guess
//! ([`project_rolling`]). A frame rendered into several outputs has that
//! landing tabulated once, over its mid-readout pixels ([`LandingGrid`]).
//!
//! The readout time itself is given (`readout_ms`, [`ShutterParams`]) or
//! estimated from the footage (`crate::readout`, above the stabilizer).

mod ease;
#[cfg(test)]
pub(crate) mod fixtures;
mod landing;
mod motion;
mod params;
mod project;
mod row_time;
#[cfg(test)]
mod tests;
mod trajectory;

pub use ease::{GaugeEase, EASE_FRAMES};
pub use landing::{LandingGrid, LANDING_GRID_STEP};
pub use motion::{row_fraction, IntraFrame, INTRA_TERMS};
pub use params::{ShutterParams, MAX_READOUT_MS};
pub use project::{project_rolling, RollingProjector, FIXED_POINT_STEPS, FIXED_POINT_TOLERANCE_PX};
pub use row_time::RowTime;
pub use trajectory::{TrajectorySmoother, TRAJECTORY_FRAMES};
