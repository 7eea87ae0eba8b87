//! Integer sums of warped frames: the averaging buffer, and the saccade mode's
//! per-frame slots that are added to and subtracted from it.

use super::Warper;
use crate::image::FrameRef;
use nalgebra::Matrix3;

/// Per-pixel sums of warped frames: the averaging buffer.
#[derive(Clone, Debug, Default)]
pub struct Accumulator {
    /// 8.8 fixed-point channel sums, 3 per pixel.
    pub sum: Vec<u32>,
    /// Frames that covered each pixel.
    pub count: Vec<u8>,
}

impl Accumulator {
    /// Zeroes the buffer for `n` pixels.
    pub fn reset(&mut self, n: usize) {
        self.sum.clear();
        self.sum.resize(3 * n, 0);
        self.count.clear();
        self.count.resize(n, 0);
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
#[derive(Clone, Debug, Default)]
pub struct WarpedFrame {
    /// Source frame index this slot holds.
    pub index: u64,
    /// 8.8 fixed-point samples (3 per pixel) of covered pixels.
    pub value: Vec<u16>,
    /// 1 where the frame covered the pixel.
    pub covered: Vec<u8>,
}

impl WarpedFrame {
    /// Warps `frame` into this slot (reusing its buffers) with the scalar
    /// sampler: the reference [`Warper::warp_into_slot`] is tested against.
    pub fn fill(
        &mut self,
        warper: &mut Warper,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        index: u64,
    ) {
        let (w, h) = warper.output_size();
        self.index = index;
        self.value.clear();
        self.value.resize(3 * w * h, 0);
        self.covered.clear();
        self.covered.resize(w * h, 0);
        let (value, covered) = (&mut self.value, &mut self.covered);
        warper.warp(frame, m, |i, rgb| {
            value[3 * i] = rgb[0] as u16;
            value[3 * i + 1] = rgb[1] as u16;
            value[3 * i + 2] = rgb[2] as u16;
            covered[i] = 1;
        });
    }

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
