//! The average of one plane, or a pair of planes, of several planar frames.

use super::finish::{finish_gray_row, finish_merged_gray_row, merged_gray_pixels};
use super::supersample::Target;
use super::{Warper, MAX_FRAMES};
use crate::render::kernels::{Geometry, FRAME_PADDING};
use nalgebra::Matrix3;

impl Warper {
    /// Renders the average of one plane of several planar frames: `plane_at(i)`
    /// is frame `i`'s plane (`width x height` bytes, rows packed, followed by at
    /// least [`FRAME_PADDING`] readable bytes for the vector kernel, else it
    /// runs scalar), sampled with this warper's cameras (the plane's) through
    /// `rotations[i]`. Writes the rounded average into `out` (this warper's
    /// output size) and the covering frames per pixel into `coverage` (resized);
    /// pixels no frame covers get `fill`. Returns how many pixels every frame covers.
    /// Supersampled: as [`Warper::average_into`].
    #[allow(clippy::too_many_arguments)]
    pub fn average_plane_into<'a, F: Fn(usize) -> &'a [u8]>(
        &mut self,
        plane_at: F,
        width: usize,
        height: usize,
        rotations: &[Matrix3<f64>],
        out: &mut [u8],
        coverage: &mut Vec<u8>,
        fill: u8,
    ) -> usize {
        let fine_len = self.out.width * self.out.height;
        let full = rotations.len() as u8;
        self.supersample_render(
            (out, coverage),
            |w, target| {
                let (out, coverage) = target.image(fine_len);
                let ow = w.out.width;
                let (maps, n_frames) = w.begin_render(rotations, coverage);
                let mut datas: [&[u8]; MAX_FRAMES] = [&[]; MAX_FRAMES];
                for (f, d) in datas.iter_mut().enumerate().take(n_frames) {
                    let p = plane_at(f);
                    if p.len() >= width * height {
                        *d = p;
                    }
                }
                let pass = w.pass(
                    &maps[..n_frames],
                    &datas[..n_frames],
                    Geometry::plane(width, height, 1),
                    height,
                );
                let merged = w.deghost.filter(|_| n_frames > 1);
                let complete =
                    w.for_each_row(out, ow, coverage, |w, scratch, v, out_row, cov_row| {
                        scratch.fit(n_frames, ow, pass.tables, merged.is_some());
                        if let Some(deghost) = merged {
                            w.merge_row(&pass, None, v, scratch, true, deghost);
                            finish_merged_gray_row(
                                w.kernel, pass.n8, scratch, out_row, cov_row, full, fill,
                            )
                        } else {
                            w.accumulate_row(&pass, None, v, scratch, true);
                            finish_gray_row(
                                w.kernel, &pass, scratch, 0, out_row, cov_row, full, fill,
                            )
                        }
                    });
                w.maps = maps;
                complete
            },
            |w, fine, (out, coverage)| {
                w.finish_fine(&fine.image, &fine.coverage, 1, full, out, coverage)
            },
        )
    }

    /// [`Warper::average_plane_into`] of two planes of one size through the
    /// same rotations (the U and V planes of 4:2:0 frames): `planes_at(i)` is
    /// frame `i`'s pair, the averages go to `out_a` and `out_b`, the covering
    /// frames (the same for both) to `coverage`. The vector kernels sample both
    /// planes along a row at once, finding each pixel's taps once (see
    /// [`Kernel::accumulate_row_gray_pair`](crate::render::kernels::Kernel::accumulate_row_gray_pair),
    /// and `merge_row_gray_pair` for ghost-free averaging, each plane weighted by
    /// its own agreement); unpadded planes take the planes one after the other. Returns how many
    /// pixels every frame covers. Supersampled: as [`Warper::average_into`].
    #[allow(clippy::too_many_arguments)]
    pub fn average_plane_pair_into<'a, F: Fn(usize) -> (&'a [u8], &'a [u8])>(
        &mut self,
        planes_at: F,
        width: usize,
        height: usize,
        rotations: &[Matrix3<f64>],
        out_a: &mut [u8],
        out_b: &mut [u8],
        coverage: &mut Vec<u8>,
        fill: u8,
    ) -> usize {
        let n_frames = rotations.len().min(MAX_FRAMES);
        let mut datas: [[&[u8]; MAX_FRAMES]; 2] = [[&[]; MAX_FRAMES]; 2];
        for f in 0..n_frames {
            let (a, b) = planes_at(f);
            for (d, p) in datas.iter_mut().zip([a, b]) {
                if p.len() >= width * height {
                    d[f] = p;
                }
            }
        }
        let padded = |d: &[&[u8]]| d.iter().all(|p| p.len() >= width * height + FRAME_PADDING);
        let merged = self.deghost.filter(|_| n_frames > 1);
        let fused = self.kernel.is_vectorized()
            && padded(&datas[0][..n_frames])
            && padded(&datas[1][..n_frames]);
        if !fused {
            let [a, b] = datas;
            let complete =
                self.average_plane_into(|i| a[i], width, height, rotations, out_a, coverage, fill);
            self.average_plane_into(|i| b[i], width, height, rotations, out_b, coverage, fill);
            return complete;
        }
        let full = rotations.len() as u8;
        let fine_len = self.out.width * self.out.height;
        self.supersample_render(
            (out_a, out_b, coverage),
            |w, target| {
                let (out_a, out_b, coverage) = match target {
                    Target::Caller(buffers) => buffers,
                    Target::Fine(fine) => fine.pair(fine_len),
                };
                let (ow, oh) = (w.out.width, w.out.height);
                let (maps, _) = w.begin_render(rotations, coverage);
                let geom = Geometry::plane(width, height, 1);
                let pass_a = w.pass(&maps[..n_frames], &datas[0][..n_frames], geom, height);
                let pass_b = w.pass(&maps[..n_frames], &datas[1][..n_frames], geom, height);
                // The pair's rows side by side in one buffer, so that the rows can be
                // shared out among threads as one image; then copied to their planes.
                let mut rows = std::mem::take(&mut w.pair_rows);
                rows.resize(2 * ow * oh, 0);
                let complete = w.for_each_row(
                    &mut rows,
                    2 * ow,
                    coverage,
                    |w, scratch, v, out_row, cov_row| {
                        scratch.fit(n_frames, ow, pass_a.tables, merged.is_some());
                        let (row_a, row_b) = out_row.split_at_mut(ow);
                        if let Some(deghost) = merged {
                            w.merge_row(&pass_a, Some(&pass_b), v, scratch, true, deghost);
                            let (k, n8) = (w.kernel, pass_a.n8);
                            // The pair's one coverage, written once (by the first plane, last).
                            merged_gray_pixels(k, n8, scratch, 1, row_b, cov_row, fill);
                            return finish_merged_gray_row(
                                k, n8, scratch, row_a, cov_row, full, fill,
                            );
                        }
                        w.accumulate_row(&pass_a, Some(&pass_b), v, scratch, true);
                        let complete = finish_gray_row(
                            w.kernel, &pass_a, scratch, 0, row_a, cov_row, full, fill,
                        );
                        finish_gray_row(w.kernel, &pass_b, scratch, 1, row_b, cov_row, full, fill);
                        complete
                    },
                );
                for ((pair, a), b) in rows
                    .chunks_exact(2 * ow)
                    .zip(out_a.chunks_exact_mut(ow))
                    .zip(out_b.chunks_exact_mut(ow))
                {
                    a.copy_from_slice(&pair[..ow]);
                    b.copy_from_slice(&pair[ow..]);
                }
                w.pair_rows = rows;
                w.maps = maps;
                complete
            },
            |w, fine, (out_a, out_b, coverage)| {
                let complete = w.finish_fine(&fine.image, &fine.coverage, 1, full, out_a, coverage);
                w.finish_fine(&fine.image_b, &fine.coverage, 1, full, out_b, coverage);
                complete
            },
        )
    }
}
