//! Template building: per pyramid level, the strongest-gradient pixel of each
//! block and its steepest-descent images.
//!
//! Per level, only the strongest-gradient pixel of each small block is used
//! (at most `max_points`): low-gradient pixels carry almost no information
//! about the rotation, and skipping them makes tracking several times faster.

use super::intrinsics::Intrinsics;
use super::rectify::rectify_template;
use super::state::LevelTemplate;
use super::vote::is_static;
use super::Tracker;
use crate::image::GrayImage;
use crate::pyramid::Pyramid;
use crate::shutter::IntraFrame;

/// Gradient magnitude (per pixel, intensity units) under which a pixel carries
/// no usable alignment information: ~0.5/255, the 8-bit quantisation step.
pub(super) const MIN_GRADIENT: f32 = 0.5 / 255.0;

impl Tracker {
    /// Makes `pyr` the template: selects pixels and precomputes steepest descent.
    pub(super) fn set_template(&mut self, pyr: &Pyramid) {
        self.frames_since_reset = 0;
        // The new template is rectified with the gauge-corrected motion; with a
        // slow pace where the readout motion is too small to be observed (see
        // [`OBSERVABLE_READOUT_PX`]), with the motion the last rate predicts:
        // frames are aligned to the template and estimated relative to it, so
        // what the estimate absorbed besides the readout (looming, parallax)
        // would otherwise pass on to every later template and add up.
        self.gauge_tpl = IntraFrame::ZERO;
        let rectified = if self.fast_motion() || !self.readout_unobservable() {
            self.intra
        } else {
            self.path_of_rate(&self.rate)
        };
        self.tpl_path = rectified;
        let mut k = self.base;
        let votes = if self.params.reject_static {
            Some((&self.static_votes[..], self.width))
        } else {
            None
        };
        for level in 0..self.n_levels {
            let img = &pyr.levels[level];
            build_level_template(
                img,
                k,
                self.params.max_points,
                &mut self.score,
                votes.map(|(v, w)| (v, w, level)),
                &mut self.template[level],
            );
            if let Some(rows) = &self.rolling {
                rectify_template(
                    &mut self.template[level],
                    rows,
                    self.row_tables.get(level),
                    level,
                    &rectified,
                );
            }
            k = k.halved();
        }
    }
}

/// Fills `tpl` from `img`: per block, the pixel of largest gradient.
///
/// Two passes: a score per pixel (the squared central-difference gradient,
/// or -1 where the pixel cannot be chosen), in straight loops down the rows
/// that vectorize, then the first pixel of highest score in each block. (One
/// loop with the four tests chained per pixel ran scalar, and branched on
/// each: it cost as much as all the frame's Gauss-Newton evaluations.)
pub(super) fn build_level_template(
    img: &GrayImage,
    k: Intrinsics,
    max_points: usize,
    score: &mut Vec<f32>,
    static_votes: Option<(&[f32], usize, usize)>,
    tpl: &mut LevelTemplate,
) {
    tpl.k = Some(k);
    tpl.width = img.width;
    tpl.loc.clear();
    tpl.xs.clear();
    tpl.ys.clear();
    tpl.zs.clear();
    tpl.tv.clear();
    for a in &mut tpl.sd {
        a.clear();
    }
    let (w, h) = (img.width, img.height);
    if w < 3 || h < 3 || img.data.len() < w * h {
        return;
    }
    let data = &img.data[..w * h];
    // Central-difference gradient (a per-pixel derivative) from a pixel's
    // left, right, upper and lower neighbours: one formula for the scores and
    // the chosen pixels' steepest-descent images.
    let gradient = |l: f32, r: f32, up: f32, down: f32| (0.5 * (r - l), 0.5 * (down - up));
    // Candidates: gradient above the quantisation step, on a valid pixel
    // (NaN compares false: a pixel next to an invalid one is never chosen),
    // and not camera-fixed; the border's scores are never read.
    let min_g2 = MIN_GRADIENT * MIN_GRADIENT;
    score.clear();
    score.resize(w * h, -1.0);
    for v in 1..h - 1 {
        let (up, row, down) = (
            &data[(v - 1) * w..v * w],
            &data[v * w..(v + 1) * w],
            &data[(v + 1) * w..(v + 2) * w],
        );
        let out = &mut score[v * w..(v + 1) * w];
        for u in 1..w - 1 {
            let (gx, gy) = gradient(row[u - 1], row[u + 1], up[u], down[u]);
            let g2 = gx * gx + gy * gy;
            out[u] = if g2 > min_g2 && row[u].is_finite() {
                g2
            } else {
                -1.0
            };
        }
        if static_votes.is_some() {
            for (u, s) in out.iter_mut().enumerate() {
                if *s > 0.0 && is_static(static_votes, u, v) {
                    *s = -1.0;
                }
            }
        }
    }
    let interior = (w - 2) * (h - 2);
    let block = ((interior as f64 / max_points as f64).sqrt().ceil() as usize).max(1);
    let mut v0 = 1;
    while v0 < h - 1 {
        let mut u0 = 1;
        while u0 < w - 1 {
            // The first pixel of the block (row by row) with the highest score.
            let (mut best, mut best_score) = (usize::MAX, -1.0f32);
            let u1 = (u0 + block).min(w - 1);
            for v in v0..(v0 + block).min(h - 1) {
                for (i, &s) in score[v * w + u0..v * w + u1].iter().enumerate() {
                    if s > best_score {
                        (best, best_score) = (v * w + u0 + i, s);
                    }
                }
            }
            if best != usize::MAX {
                let i = best;
                let (u, v) = ((i % w) as f32, (i / w) as f32);
                let (x, y) = k.ray(u, v);
                let jx = [-x * y, 1.0 + x * x, -y];
                let jy = [-(1.0 + y * y), x * y, x];
                let (gx, gy) = gradient(data[i - 1], data[i + 1], data[i - w], data[i + w]);
                let mut sd = [0f32; 3];
                for a in 0..3 {
                    let du = k.fx * jx[a] + k.skew * jy[a];
                    let dv = k.fy * jy[a];
                    sd[a] = gx * du + gy * dv;
                }
                tpl.xs.push(x);
                tpl.ys.push(y);
                tpl.tv.push(data[i]);
                for (a, v) in tpl.sd.iter_mut().zip(sd) {
                    a.push(v);
                }
                tpl.loc.push(i as u32);
            }
            u0 += block;
        }
        v0 += block;
    }
}
