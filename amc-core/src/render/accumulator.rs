//! Integer sums of warped frames: the averaging buffer, and the saccade mode's
//! per-frame slots that are added to and subtracted from it.
//!
//! Plain buffers, below the warper: the warper fills them (`warper.rs` also holds
//! [`WarpedFrame::fill`]), nothing here warps.

/// Per-pixel sums of warped frames: the averaging buffer.
///
/// Interleaved frames: 3 sums and 1 count per pixel. Planar 4:2:0 frames of
/// `n` luma and `nc` chroma pixels: sums of Y (`n`), U (`nc`), V (`nc`) one
/// after the other, counts of Y (`n`) then of the chroma planes (`nc`, shared
/// by U and V). [`WarpedFrame`]s use the same layout, so adding and removing
/// them never needs to know which.
#[derive(Clone, Debug, Default)]
pub struct Accumulator {
    /// 8.8 fixed-point sums.
    pub sum: Vec<u32>,
    /// Frames that covered each pixel (the first `width * height` are the
    /// output's luma or colour pixels).
    pub count: Vec<u8>,
}

impl Accumulator {
    /// Zeroes the buffer for `n` interleaved pixels.
    pub fn reset(&mut self, n: usize) {
        self.reset_to(3 * n, n);
    }

    /// Zeroes the buffer for `sums` sums and `counts` counts.
    pub fn reset_to(&mut self, sums: usize, counts: usize) {
        self.sum.clear();
        self.sum.resize(sums, 0);
        self.count.clear();
        self.count.resize(counts, 0);
    }

    /// Writes the average into a planar 4:2:0 frame buffer of `width x height`
    /// (uncovered pixels black: Y 16, U = V 128). Returns the share of luma
    /// pixels covered by `full` frames.
    pub fn finish_yuv420_into(&self, out: &mut [u8], width: usize, height: usize, full: u8) -> f64 {
        let (cw, ch) = crate::image::chroma_size(width, height);
        let (n, nc) = (width * height, cw * ch);
        let (oy, ou, ov) = crate::image::yuv_planes_mut(width, height, out);
        let (cy, cc) = self.count.split_at(n);
        let planes = [
            (oy, &self.sum[..n], cy, 16u8),
            (ou, &self.sum[n..n + nc], cc, 128),
            (ov, &self.sum[n + nc..n + 2 * nc], cc, 128),
        ];
        for (dst, sum, count, fill) in planes {
            for ((o, &s), &k) in dst.iter_mut().zip(sum).zip(count) {
                *o = if k == 0 {
                    fill
                } else {
                    (s as f32 * (1.0 / (256.0 * k as f32)) + 0.5) as u8
                };
            }
        }
        let complete = cy.iter().filter(|&&k| k >= full).count();
        complete as f64 / n.max(1) as f64
    }

    /// Writes the average into an interleaved frame buffer (`channels` 3 or 4);
    /// uncovered pixels are black. Returns the share of pixels covered by `full` frames.
    pub fn finish_into(&self, out: &mut [u8], channels: usize, full: u8) -> f64 {
        let mut inv = [0f32; 256];
        for (k, v) in inv.iter_mut().enumerate().skip(1) {
            *v = 1.0 / (256.0 * k as f32);
        }
        let mut complete = 0usize;
        for ((px, s), &n) in out
            .chunks_exact_mut(channels)
            .zip(self.sum.chunks_exact(3))
            .zip(&self.count)
        {
            let k = inv[n as usize];
            px[0] = (s[0] as f32 * k + 0.5) as u8;
            px[1] = (s[1] as f32 * k + 0.5) as u8;
            px[2] = (s[2] as f32 * k + 0.5) as u8;
            if channels == 4 {
                px[3] = 255;
            }
            complete += (n >= full) as usize;
        }
        complete as f64 / self.count.len().max(1) as f64
    }
}

/// One frame warped into the (fixed) saccade view, kept to subtract it later.
/// Laid out as the [`Accumulator`] it is added to.
#[derive(Clone, Debug, Default)]
pub struct WarpedFrame {
    /// Source frame index this slot holds.
    pub index: u64,
    /// 8.8 fixed-point samples of covered pixels (0 elsewhere).
    pub value: Vec<u16>,
    /// 1 where the frame covered the pixel.
    pub covered: Vec<u8>,
}

impl WarpedFrame {
    /// Adds (`add = true`) or removes this slot from an accumulator.
    /// Uncovered pixels hold zeros, so no per-pixel branch is needed.
    pub fn apply(&self, acc: &mut Accumulator, add: bool) {
        if add {
            for (s, &v) in acc.sum.iter_mut().zip(&self.value) {
                *s += v as u32;
            }
            for (n, &c) in acc.count.iter_mut().zip(&self.covered) {
                *n += c;
            }
        } else {
            for (s, &v) in acc.sum.iter_mut().zip(&self.value) {
                *s -= v as u32;
            }
            for (n, &c) in acc.count.iter_mut().zip(&self.covered) {
                *n -= c;
            }
        }
    }
}
