//! Saccade mode's rendering: one warped slot per frame of the window and a
//! running sum, re-centred when the coverage drops.

use super::params::StabilizerParams;
use super::rendering::Rendering;
use super::Buffered;
use crate::render::robust::weighted_average;
use crate::render::Deghost;
use crate::so3::Rot;
use nalgebra::Matrix3;
use std::collections::VecDeque;

/// Most saccade slots merged at once (the range of `n_avg`).
pub(super) const MAX_SLOTS: usize = 64;

impl Rendering {
    /// The render step of saccade mode for output `j` (the ring's frames
    /// `first..=pos`, of size `src`, at the zoom `zinv`): the slots brought up
    /// to date in the held view `r_view`, re-centred on the output's own
    /// frame when `saccade` is due or the coverage drops (`saccade` then set,
    /// and `r_view` the new view); returns the share of pixels every frame
    /// covers.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn render_saccade(
        &mut self,
        ring: &VecDeque<Buffered>,
        params: &StabilizerParams,
        src: (usize, usize),
        j: u64,
        (first, pos): (usize, usize),
        r_view: &mut Rot,
        saccade: &mut bool,
        zinv: &Matrix3<f64>,
    ) -> f64 {
        let r_est = ring[pos].r_est;
        if *saccade {
            self.last_saccade = Some(j);
            self.saccade_view = Some(r_est);
            self.slots.drain(..).for_each(|s| self.spare_slots.push(s));
            *r_view = r_est;
        }
        self.saccade_update(ring, src, first, pos, r_view, zinv);
        let full = self.slots.len() as u8;
        let mut vf = self.finish_saccade(full);
        // After a saccade the older frames of the window cannot cover the new
        // view; coverage by every averaged frame recovers only once the
        // window has refilled, so the next saccade waits `n_avg` frames
        // (without this, strong motion re-centres on every frame).
        let refractory = self
            .last_saccade
            .is_some_and(|s| j < s + params.render.n_avg as u64);
        if vf < params.view.saccade_coverage && j > 0 && !refractory {
            self.last_saccade = Some(j);
            // Re-centre the view on the current estimate and rebuild the sums.
            *saccade = true;
            self.saccade_view = Some(r_est);
            self.slots.drain(..).for_each(|s| self.spare_slots.push(s));
            self.saccade_update(ring, src, first, pos, &r_est, zinv);
            let full = self.slots.len() as u8;
            vf = self.finish_saccade(full);
        }
        vf
    }

    /// Writes the saccade sums into the output frame; returns the share of
    /// pixels covered by `full` frames.
    pub(super) fn finish_saccade(&mut self, full: u8) -> f64 {
        let (ow, oh) = (self.out_cam.width, self.out_cam.height);
        if let Some(deghost) = self.warper.deghost().filter(|_| self.slots.len() > 1) {
            self.finish_saccade_merged(deghost, full)
        } else if self.output.format.is_planar() {
            self.acc
                .finish_yuv420_into(&mut self.output.data, ow, oh, full)
        } else {
            let channels = self.output.format.channels();
            self.acc.finish_into(&mut self.output.data, channels, full)
        }
    }

    /// [`Rendering::finish_saccade`] with ghost-free averaging: merges the
    /// slots against the newest one, plane by plane (or the three interleaved
    /// channels at once), into the output frame.
    pub(super) fn finish_saccade_merged(&mut self, deghost: Deghost, full: u8) -> f64 {
        let (ow, oh) = (self.out_cam.width, self.out_cam.height);
        let n_px = ow * oh;
        let n = self.slots.len().min(MAX_SLOTS);
        let reference = n - 1;
        let slots = &self.slots;
        let (sum, weight) = (&mut self.merged_sum, &mut self.merged_weight);
        if self.output.format.is_planar() {
            let (cw, ch) = crate::image::chroma_size(ow, oh);
            let nc = cw * ch;
            sum.resize(n_px, 0);
            weight.resize(n_px, 0);
            let (oy, ou, ov) = crate::image::yuv_planes_mut(ow, oh, &mut self.output.data);
            // (output plane, its values' offset in a slot, its coverage's, size, fill)
            let planes = [
                (oy, 0, 0, n_px, 16u8),
                (ou, n_px, n_px, nc, 128),
                (ov, n_px + nc, n_px, nc, 128),
            ];
            for (out, at, cov_at, len, fill) in planes {
                let mut values: [&[u16]; MAX_SLOTS] = [&[]; MAX_SLOTS];
                let mut covered: [&[u8]; MAX_SLOTS] = [&[]; MAX_SLOTS];
                for (f, slot) in slots.iter().take(n).enumerate() {
                    values[f] = &slot.value[at..at + len];
                    covered[f] = &slot.covered[cov_at..cov_at + len];
                }
                deghost.merge_plane(&values[..n], &covered[..n], reference, len, sum, weight);
                for ((o, &s), &w) in out.iter_mut().zip(&sum[..len]).zip(&weight[..len]) {
                    *o = weighted_average(s, w, fill);
                }
            }
        } else {
            let channels = self.output.format.channels();
            sum.resize(3 * n_px, 0);
            weight.resize(n_px, 0);
            let mut values: [[&[u16]; 3]; MAX_SLOTS] = [[&[]; 3]; MAX_SLOTS];
            let mut covered: [&[u8]; MAX_SLOTS] = [&[]; MAX_SLOTS];
            for (f, slot) in slots.iter().take(n).enumerate() {
                let v = &slot.value[..];
                values[f] = [v, &v[1..], &v[2..]];
                covered[f] = &slot.covered;
            }
            let (sr, rest) = sum.split_at_mut(n_px);
            let (sg, sb) = rest.split_at_mut(n_px);
            deghost.merge_rgb(
                &values[..n],
                3,
                &covered[..n],
                reference,
                n_px,
                [sr, sg, sb],
                weight,
            );
            for (i, px) in self.output.data[..channels * n_px]
                .chunks_exact_mut(channels)
                .enumerate()
            {
                let w = weight[i];
                px[0] = weighted_average(sr[i], w, 0);
                px[1] = weighted_average(sg[i], w, 0);
                px[2] = weighted_average(sb[i], w, 0);
                if channels == 4 {
                    px[3] = 255;
                }
            }
        }
        let complete = self.acc.count[..n_px]
            .iter()
            .filter(|&&k| k >= full)
            .count();
        complete as f64 / n_px.max(1) as f64
    }

    /// Saccade mode's recursive update: keeps one warped slot per frame of the
    /// window, warps only frames not yet warped into `view`, and maintains the
    /// running sum by adding the newest and subtracting the oldest.
    pub(super) fn saccade_update(
        &mut self,
        ring: &VecDeque<Buffered>,
        src: (usize, usize),
        first: usize,
        pos: usize,
        view: &Rot,
        zinv: &nalgebra::Matrix3<f64>,
    ) {
        let (ow, oh) = (self.out_cam.width, self.out_cam.height);
        let n_px = ow * oh;
        let planar = self.output.format.is_planar();
        let (cw, ch) = crate::image::chroma_size(ow, oh);
        let nc = cw * ch;
        let first_index = ring[first].index;
        if self.slots.is_empty() {
            if planar {
                self.acc.reset_to(n_px + 2 * nc, n_px + nc);
            } else {
                self.acc.reset(n_px);
            }
        }
        while self.slots.front().is_some_and(|s| s.index < first_index) {
            if let Some(old) = self.slots.pop_front() {
                old.apply(&mut self.acc, false);
                self.spare_slots.push(old);
            }
        }
        let have_until = self
            .slots
            .back()
            .map(|s| s.index + 1)
            .unwrap_or(first_index);
        for b in ring.range(first..=pos) {
            if b.index < have_until {
                continue;
            }
            let m = b.r_est.matrix().transpose() * view.matrix() * zinv;
            let rows = std::slice::from_ref(&b.rows);
            self.warper.set_readout_rows(rows);
            self.chroma.set_readout_rows(rows);
            let mut slot = self.spare_slots.pop().unwrap_or_default();
            if planar {
                let (w, h) = (src.0, src.1);
                let (scw, sch) = crate::image::chroma_size(w, h);
                let (u_at, v_at) = crate::image::yuv_plane_offsets(w, h);
                slot.index = b.index;
                slot.value.clear();
                slot.value.resize(n_px + 2 * nc, 0);
                slot.covered.clear();
                slot.covered.resize(n_px + nc, 0);
                self.chroma_cov.resize(nc, 0);
                let (vy, vc) = slot.value.split_at_mut(n_px);
                let (vu, vv) = vc.split_at_mut(nc);
                let (cy, cc) = slot.covered.split_at_mut(n_px);
                let data = &b.frame.data;
                self.warper.warp_plane_into(data, w, h, &m, vy, cy);
                self.chroma
                    .warp_plane_into(&data[u_at..], scw, sch, &m, vu, cc);
                self.chroma
                    .warp_plane_into(&data[v_at..], scw, sch, &m, vv, &mut self.chroma_cov);
            } else {
                self.warper
                    .warp_into_slot(&b.frame.as_ref(), &m, &mut slot, b.index);
            }
            slot.apply(&mut self.acc, true);
            self.slots.push_back(slot);
        }
    }
}
