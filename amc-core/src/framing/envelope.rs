//! The zoom over time: follows the need without pumping.
//!
//! `auto`, per output frame at time `t` with need `n(t)` (the need of the
//! smoothed view, before any pull toward the camera):
//! ```text
//! target(t) = min(z_max, max { n(t') : t - ZOOM_HOLD_S < t' <= t })   hold the highest recent need
//! z(t)      = z(t_prev) + clamp(target - z(t_prev), -ZOOM_FALL_PER_S dt, ZOOM_RISE_PER_S dt)
//! ```
//! starting at `z_max = 1 / (1 - max_crop)` (the budget: the first frames are
//! steady, and the zoom eases out to what the clip needs). So the zoom changes
//! by at most `ZOOM_RISE_PER_S * dt` between frames (0.0083 at 60 fps, 0.017
//! at 30 fps) and eases out slowly after a turn, a second after the need has
//! gone; where the need rises faster than the zoom may, the view is pulled
//! toward the camera instead (`constrain.rs`), so no border shows.

use super::params::{FramingParams, Zoom};
use std::collections::VecDeque;

/// Fastest zoom-in, zoom units per second.
pub const ZOOM_RISE_PER_S: f64 = 0.5;
/// Fastest zoom-out, zoom units per second (slow: zooming out is never urgent).
pub const ZOOM_FALL_PER_S: f64 = 0.1;
/// How long a need is held before the zoom may ease out, seconds.
pub const ZOOM_HOLD_S: f64 = 1.0;

/// The framing state of one clip: the zoom of each output frame in turn.
#[derive(Clone, Debug)]
pub struct Framer {
    params: FramingParams,
    zoom: f64,
    /// Recent needs `(t, need)`, oldest first, within [`ZOOM_HOLD_S`].
    recent: VecDeque<(f64, f64)>,
    last_t: Option<f64>,
    fixed: Option<f64>,
}

impl Framer {
    /// A framer for `params`.
    pub fn new(params: FramingParams) -> Self {
        let zoom = params.max_zoom();
        Self {
            params,
            zoom,
            recent: VecDeque::new(),
            last_t: None,
            fixed: None,
        }
    }

    /// Holds the zoom at `zoom` for the whole clip (clamped to `1..=z_max`):
    /// `static`'s second pass, and the saccade mode's fixed framing.
    pub fn set_fixed(&mut self, zoom: f64) {
        let z = zoom.clamp(1.0, self.params.max_zoom());
        self.fixed = Some(z);
        self.zoom = z;
    }

    /// The zoom held by [`Framer::set_fixed`], if any.
    pub fn fixed(&self) -> Option<f64> {
        self.fixed
    }

    /// The zoom of the output at `t` whose smoothed view needs `need`.
    /// `none` always answers 1 (the margin is in the output camera).
    pub fn next(&mut self, t: f64, need: f64) -> f64 {
        if self.params.zoom == Zoom::None {
            return 1.0;
        }
        if let Some(z) = self.fixed {
            return z;
        }
        let z_max = self.params.max_zoom();
        while self
            .recent
            .front()
            .is_some_and(|&(t0, _)| t0 <= t - ZOOM_HOLD_S)
        {
            self.recent.pop_front();
        }
        // A monotone deque: only needs that may still be the highest are kept.
        while self.recent.back().is_some_and(|&(_, n)| n <= need) {
            self.recent.pop_back();
        }
        self.recent.push_back((t, need));
        let held = self.recent.front().map_or(need, |&(_, n)| n);
        let target = held.clamp(1.0, z_max);
        if let Some(prev) = self.last_t.filter(|&p| t > p) {
            let dt = t - prev;
            let step = (target - self.zoom).clamp(-ZOOM_FALL_PER_S * dt, ZOOM_RISE_PER_S * dt);
            self.zoom = (self.zoom + step).clamp(1.0, z_max);
        }
        self.last_t = Some(t);
        self.zoom
    }
}
