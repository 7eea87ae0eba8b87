//! Supersampling: every entry point renders on the render grid through one
//! helper ([`Warper::supersample_render`]), into the caller's buffers when
//! each output pixel is one sample, else into the fine buffers ([`Fine`])
//! whose `S x S` blocks are then averaged into the caller's.

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

impl Fine {
    /// The image, `len` values, and its coverage.
    pub(super) fn image(&mut self, len: usize) -> (&mut [u8], &mut Vec<u8>) {
        self.image.resize(len, 0);
        (&mut self.image, &mut self.coverage)
    }

    /// Both planes of a pair, `len` values each, and their coverage.
    pub(super) fn pair(&mut self, len: usize) -> (&mut [u8], &mut [u8], &mut Vec<u8>) {
        self.image.resize(len, 0);
        self.image_b.resize(len, 0);
        (&mut self.image, &mut self.image_b, &mut self.coverage)
    }

    /// The slot's first `len` values and coverage flags (one plane).
    pub(super) fn plane_slot(&mut self, len: usize) -> (&mut [u16], &mut [u8]) {
        self.slot.value.resize(len, 0);
        self.slot.covered.resize(len, 0);
        (&mut self.slot.value[..len], &mut self.slot.covered[..len])
    }
}

/// Where a render on the render grid writes.
pub(super) enum Target<'f, O> {
    /// The caller's buffers (one sample per output pixel: the render grid is
    /// the output).
    Caller(O),
    /// The fine buffers, averaged into the caller's afterwards.
    Fine(&'f mut Fine),
}

impl Warper {
    /// Runs `render` on the render grid: into the caller's buffers `out` with
    /// one sample per output pixel (`S = 1`, the output is the plain render),
    /// else into the fine buffers, whose `S x S` blocks `down` then averages
    /// into `out`; returns what `render`, or `down`, returns.
    pub(super) fn supersample_render<O, T>(
        &mut self,
        out: O,
        render: impl FnOnce(&mut Self, Target<'_, O>) -> T,
        down: impl FnOnce(&Self, &Fine, O) -> T,
    ) -> T {
        if self.supersample == 1 {
            return render(self, Target::Caller(out));
        }
        let mut fine = std::mem::take(&mut self.fine);
        render(self, Target::Fine(&mut fine));
        let result = down(self, &fine, out);
        self.fine = fine;
        result
    }

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
