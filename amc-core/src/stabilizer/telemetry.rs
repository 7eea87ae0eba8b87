//! What the stabilizer reports about each output frame.

use crate::tracker::TrackInfo;
use serde::{Deserialize, Serialize};

/// What the stabilizer knows about one output frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Telemetry {
    /// Index of the input frame this output shows (0-based).
    pub frame: u64,
    /// Its timestamp, seconds.
    pub t: f64,
    /// Rotation vector (radians) of the estimated orientation `R_hat_{0,j}`.
    pub r_est: [f64; 3],
    /// Rotation vector (radians) of the view `R^view_{0,j}`.
    pub r_view: [f64; 3],
    /// Body angular velocity of the estimate, `log(R_{0,j-1}^T R_{0,j}) / dt`, rad/s.
    pub rate_est: [f64; 3],
    /// Body angular velocity of the view, rad/s.
    pub rate_view: [f64; 3],
    /// Share of output pixels covered by every averaged frame.
    pub valid_fraction: f64,
    /// Frames averaged into this output.
    pub frames_averaged: usize,
    /// True when the saccade view was re-centred at this frame.
    pub saccade: bool,
    /// Zoom of the output: `1 / zoom` is the share of the source's width it
    /// keeps (with `zoom = none`, `1 / (1 - 2 margin)`).
    pub zoom: f64,
    /// Output pixels no averaged frame covers (shown black; 0 with `zoom`
    /// `auto` or `static`); for planar frames, luma pixels.
    pub uncovered: u64,
    /// Rotation vector (radians, this frame's camera axes) of the camera's
    /// rotation across its readout, first row to last (`a(1/2) - a(-1/2)` of
    /// [`IntraFrame`](crate::shutter::IntraFrame); about the readout time times the angular velocity at
    /// mid-readout). Zero with a global shutter.
    pub readout_rotation: [f64; 3],
    /// Tracking quality.
    pub track: TrackInfo,
}
