//! Camera-fixed regions: the static-pixel vote. Camera-fixed regions (a car's
//! dashboard, an FPV on-screen display, propellers in view) agree with "no
//! rotation" and pull a least-squares estimate toward zero. After each frame,
//! every template pixel whose image moved by more than
//! [`STATIC_MIN_DISPLACEMENT_PX`] votes: if the current frame at the *same*
//! location explains it much better than at the rotated location (`|e_id| <
//! |e_rot| / 2`), it is camera-fixed. Votes are averaged per image location
//! with an exponential moving average, and locations whose average exceeds
//! [`STATIC_THRESHOLD`] are left out of later templates.

use super::Tracker;
use crate::image::GrayImage;
use crate::so3::Rot;

/// A pixel votes on being camera-fixed only if the rotation moved it this far
/// (pixels, finest level): below this "fixed" and "rotating" look alike.
pub const STATIC_MIN_DISPLACEMENT_PX: f32 = 0.3;

/// Residuals below this (intensity units, ~1.5/255) are noise, not evidence.
pub(super) const STATIC_NOISE: f32 = 1.5 / 255.0;

/// Weight of one frame's vote in the per-location moving average.
pub(super) const STATIC_VOTE_GAIN: f32 = 0.25;

/// Average vote above which a location is treated as camera-fixed.
pub const STATIC_THRESHOLD: f32 = 0.3;

impl Tracker {
    /// Updates the camera-fixed votes from the finest level at the final estimate.
    pub(super) fn vote_static(&mut self, img: &GrayImage, r: &Rot) {
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
}

/// True when level pixel `(u, v)` lies on a camera-fixed location (votes are
/// kept at the finest level; a level-`l` pixel's centre is at `2^l u + (2^l - 1)/2`).
pub(super) fn is_static(votes: Option<(&[f32], usize, usize)>, u: usize, v: usize) -> bool {
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
