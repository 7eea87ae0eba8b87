//! Sharpness, `sqrt(mean over pixels and R, G, B of |Sobel C / 8|^2)`, as
//! exact integer sums over the 8-bit channel rows.
//!
//! With `C = c / 255` for a channel's byte `c`, the Sobel responses of the
//! bytes are integers, `gx, gy` in `-1020..=1020`, and
//! `|Sobel C / 8|^2 = (gx^2 + gy^2) / (64 255^2)`: summing the integers is
//! exact, and the one division comes at the end. The operator is the
//! separable one of `sobel.rs`, in 16-bit lanes, `gx^2 + gy^2` in 32 bits.
//! Rows stream through a ring of three, so nothing the size of a frame is
//! written.

use super::sobel::{columns_into, magnitude_sq};
use crate::color::yuv420p_rgb_row_into;
use crate::image::FrameRef;

/// The divisor that turns a sum of `gx^2 + gy^2` of bytes into one of
/// `|Sobel C / 8|^2` of intensities in `[0, 1]`.
pub(super) const SCALE: f64 = 64.0 * 255.0 * 255.0;

/// Pixels summed in 32 bits before the sum is widened: `1024 * 2 * 1020^2`
/// is below `u32::MAX`.
const BLOCK: usize = 1024;

/// The last three rows of R, G and B, and reused scratch.
#[derive(Clone, Debug, Default)]
pub(super) struct ChannelRows {
    /// `channels[ch][slot]`: row `y` of channel `ch` sits in slot `y % 3`.
    channels: [[Vec<u8>; 3]; 3],
    sums: Vec<i16>,
    diffs: Vec<i16>,
}

impl ChannelRows {
    /// Row `y` of `frame`'s R, G and B into the ring (a planar frame as the
    /// RGB a player would show).
    #[inline(always)]
    pub fn fill_row(&mut self, frame: &FrameRef<'_>, y: usize) {
        let w = frame.width;
        let slot = y % 3;
        let [r, g, b] = &mut self.channels;
        let (r, g, b) = (&mut r[slot], &mut g[slot], &mut b[slot]);
        for row in [&mut *r, &mut *g, &mut *b] {
            row.resize(w, 0);
        }
        if frame.format.is_planar() {
            yuv420p_rgb_row_into(w, frame.height, frame.data, y, [r, g, b]);
            return;
        }
        let c = frame.format.channels();
        let px = &frame.data[y * w * c..(y + 1) * w * c];
        for (((p, r), g), b) in px.chunks_exact(c).zip(r).zip(g).zip(b) {
            (*r, *g, *b) = (p[0], p[1], p[2]);
        }
    }

    /// Sum over R, G and B of `gx^2 + gy^2` of row `y` (its rows above and
    /// below in the ring) over the interior pixels `1..w - 1` whose `interior`
    /// entry (index `x - 1`) is 1. Divide by [`SCALE`] for intensities.
    #[inline(always)]
    pub fn sum(&mut self, y: usize, interior: &[u8]) -> u64 {
        let [above, at, below] = [(y + 2) % 3, y % 3, (y + 1) % 3];
        let mut total = 0;
        for rows in &self.channels {
            total += sobel_sq_sum(
                [&rows[above], &rows[at], &rows[below]],
                interior,
                &mut self.sums,
                &mut self.diffs,
            );
        }
        total
    }
}

/// `sum of gx^2 + gy^2` of the byte rows `[above, at, below]` over the
/// interior pixels `x` in `1..w - 1` whose `valid[x - 1]` is 1; `sums` and
/// `diffs` are scratch.
#[inline(always)]
fn sobel_sq_sum(
    [above, at, below]: [&[u8]; 3],
    valid: &[u8],
    sums: &mut Vec<i16>,
    diffs: &mut Vec<i16>,
) -> u64 {
    columns_into([above, at, below], sums, diffs);
    let n = at.len() - 2;
    let mut total = 0u64;
    for start in (0..n).step_by(BLOCK) {
        let end = (start + BLOCK).min(n);
        let len = end - start;
        // Equal-length slices: no bounds checks, so the loop vectorizes.
        let (sl, sr) = (&sums[start..end], &sums[start + 2..end + 2]);
        let (dl, dc, dr) = (
            &diffs[start..end],
            &diffs[start + 1..end + 1],
            &diffs[start + 2..end + 2],
        );
        let valid = &valid[start..end];
        let mut block = 0u32;
        for i in 0..len {
            let g2 = magnitude_sq(sl[i], sr[i], dl[i], dc[i], dr[i]) as u32;
            block += if valid[i] != 0 { g2 } else { 0 };
        }
        total += block as u64;
    }
    total
}
