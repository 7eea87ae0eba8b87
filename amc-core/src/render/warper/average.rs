//! The average of several interleaved frames (RGB, RGBA) into the view.

use super::finish::{finish_merged_rgb_row, finish_rgb_row};
use super::{Warper, MAX_FRAMES};
use crate::image::FrameRef;
use crate::render::kernels::Geometry;
use nalgebra::Matrix3;

impl Warper {
    /// Renders the average of frames `frame_at(0..n)` (with `rotations[i]`, the
    /// output->source rotation of frame `i`) into `out` (interleaved,
    /// `channels` 3 or 4) in one pass: per output row the source coordinates of
    /// every frame are computed into small row buffers, then each pixel samples
    /// all frames and is written once. `coverage` receives the per-pixel count
    /// of covering frames. Returns the share of pixels covered by every frame.
    /// Supersampled: each pixel is its block's
    /// [`box_down`](super::downsample::box_down), its coverage the block's
    /// least.
    pub fn average_into<'a, F: Fn(usize) -> FrameRef<'a>>(
        &mut self,
        frame_at: F,
        rotations: &[Matrix3<f64>],
        out: &mut [u8],
        channels: usize,
        coverage: &mut Vec<u8>,
    ) -> f64 {
        let full = rotations.len() as u8;
        let fine_len = self.out.width * self.out.height * channels;
        let complete = self.supersample_render(
            (out, coverage),
            |w, target| {
                let (out, coverage) = target.image(fine_len);
                let ow = w.out.width;
                let (maps, n_frames) = w.begin_render(rotations, coverage);
                // Hoist each frame's pixels out of the per-pixel loop.
                let mut datas: [&[u8]; MAX_FRAMES] = [&[]; MAX_FRAMES];
                let first = frame_at(0);
                for (f, d) in datas.iter_mut().enumerate().take(n_frames) {
                    let fr = frame_at(f);
                    if fr.width == first.width
                        && fr.height == first.height
                        && fr.format == first.format
                    {
                        *d = fr.data;
                    }
                }
                let pass = w.pass(
                    &maps[..n_frames],
                    &datas[..n_frames],
                    Geometry::of(&first),
                    first.height,
                );
                let merged = w.deghost.filter(|_| n_frames > 1);
                let complete = w.for_each_row(
                    out,
                    ow * channels,
                    coverage,
                    |w, scratch, v, out_row, cov_row| {
                        scratch.fit(n_frames, ow, pass.tables, merged.is_some());
                        if let Some(deghost) = merged {
                            w.merge_row(&pass, None, v, scratch, false, deghost);
                            finish_merged_rgb_row(
                                w.kernel, scratch, out_row, cov_row, channels, full,
                            )
                        } else {
                            w.accumulate_row(&pass, None, v, scratch, false);
                            finish_rgb_row(
                                w.kernel, &pass, scratch, out_row, cov_row, channels, full,
                            )
                        }
                    },
                );
                w.maps = maps;
                complete
            },
            |w, fine, (out, coverage)| {
                w.finish_fine(&fine.image, &fine.coverage, channels, full, out, coverage)
            },
        );
        complete as f64 / (self.view_w * self.view_h).max(1) as f64
    }
}
