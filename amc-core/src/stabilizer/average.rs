//! The render step of stabilize, lock and none modes: the window's frames
//! warped through their rotations and averaged into the output, plane by
//! plane for planar frames.

use super::buffered::Buffered;
use super::rendering::Rendering;
use crate::so3::Rot;
use nalgebra::Matrix3;
use std::collections::VecDeque;

impl Rendering {
    /// Renders the average of the ring's frames `first..=pos` (of size `src`)
    /// seen through `r_view` at the zoom `zinv` into the output; returns the
    /// share of its pixels every frame covers.
    pub(super) fn render_average(
        &mut self,
        ring: &VecDeque<Buffered>,
        src: (usize, usize),
        (first, pos): (usize, usize),
        r_view: &Rot,
        zinv: &Matrix3<f64>,
    ) -> f64 {
        let format = self.output.format;
        let channels = format.channels();
        let (ow, oh) = (self.out_cam.width, self.out_cam.height);
        self.rotations.clear();
        self.rotations.extend(
            ring.range(first..=pos)
                .map(|b| b.r_est.matrix().transpose() * r_view.matrix() * zinv),
        );
        if format.is_planar() {
            // One geometry, three planes: Y through the luma cameras, U and V
            // through the chroma cameras, all with the same rotations.
            let (w, h) = (src.0, src.1);
            let (cw, ch) = crate::image::chroma_size(w, h);
            let (u_at, v_at) = crate::image::yuv_plane_offsets(w, h);
            let (oy, ou, ov) = crate::image::yuv_planes_mut(ow, oh, &mut self.output.data);
            // Each plane is passed with what follows it in the buffer (the
            // next planes, then the tail padding) for the kernels' gathers.
            let plane = |i: usize, at: usize| &ring[first + i].frame.data[at..];
            let (warper, chroma) = (&mut self.warper, &mut self.chroma);
            let (count, chroma_cov) = (&mut self.acc.count, &mut self.chroma_cov);
            let rotations = &self.rotations;
            // Luma and chroma at once: the rows of each are split into bands,
            // and a thread done with its luma bands takes chroma ones instead
            // of waiting for the other at the end of the luma plane.
            let (complete, ()) = super::push::join(
                || warper.average_plane_into(|i| plane(i, 0), w, h, rotations, oy, count, 16),
                || {
                    chroma.average_plane_pair_into(
                        |i| (plane(i, u_at), plane(i, v_at)),
                        cw,
                        ch,
                        rotations,
                        ou,
                        ov,
                        chroma_cov,
                        128,
                    );
                },
            );
            complete as f64 / (ow * oh).max(1) as f64
        } else {
            self.warper.average_into(
                |i| ring[first + i].frame.as_ref(),
                &self.rotations,
                &mut self.output.data,
                channels,
                &mut self.acc.count,
            )
        }
    }
}
