//! Supersampling: every entry point renders on the render grid through one
//! helper ([`Warper::supersample_render`]), into the caller's buffers when
//! each output pixel is one sample, else into the fine buffers ([`Fine`])
//! whose `S x S` blocks are then averaged into the caller's.

use super::buffers::Fine;
use super::downsample::box_down;
use super::Warper;

/// Where a render on the render grid writes.
pub(super) enum Target<'f, O> {
    /// The caller's buffers (one sample per output pixel: the render grid is
    /// the output).
    Caller(O),
    /// The fine buffers, averaged into the caller's afterwards.
    Fine(&'f mut Fine),
}

impl<'f: 'o, 'o> Target<'f, (&'o mut [u8], &'o mut Vec<u8>)> {
    /// The image (`len` values when fine) and coverage a render writes.
    pub(super) fn image(self, len: usize) -> (&'o mut [u8], &'o mut Vec<u8>) {
        match self {
            Target::Caller(buffers) => buffers,
            Target::Fine(fine) => fine.image(len),
        }
    }
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
