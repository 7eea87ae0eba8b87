//! Supersampling: the fine renders of a warper with `S > 1`.

use super::downsample::box_down;
use super::Warper;
use crate::render::accumulator::WarpedFrame;

/// The supersampled renders of a warper with `S > 1`, before their `S x S`
/// blocks are averaged into the caller's buffers (kept: a warmed-up render
/// allocates nothing).
#[derive(Clone, Debug, Default)]
pub(super) struct Fine {
    /// Image (interleaved or one plane) and its second plane (U and V pairs).
    pub(super) image: Vec<u8>,
    pub(super) image_b: Vec<u8>,
    /// Covering frames per fine pixel.
    pub(super) coverage: Vec<u8>,
    /// A saccade slot's samples and coverage (interleaved or one plane).
    pub(super) slot: WarpedFrame,
}

impl Warper {
    /// A supersampled render's last step: `image` (`channels` per pixel, with
    /// its per-pixel `fine_coverage`, on the render grid) averaged block by
    /// block into `out` and `coverage` (resized) at the output size; returns
    /// how many output pixels all `full` frames cover ([`box_down`]).
    pub(super) fn finish_fine(
        &self,
        image: &[u8],
        fine_coverage: &[u8],
        channels: usize,
        full: u8,
        out: &mut [u8],
        coverage: &mut Vec<u8>,
    ) -> usize {
        let (ow, oh) = (self.view_w, self.view_h);
        coverage.clear();
        coverage.resize(ow * oh, 0);
        box_down(
            image,
            fine_coverage,
            self.supersample,
            channels,
            (ow, oh),
            out,
            coverage,
            full,
        )
    }
}
