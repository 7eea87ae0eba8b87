//! The luma metrics, normal flow and change against the previous output, on
//! integer luma in 16-bit lanes.
//!
//! Luma is held as integers `L` with a scale `s` (intensity `L / s`): a
//! planar frame's `Y` exactly (`L = clamp(Y, 16, 235) - 16`, `s = 219`), a
//! packed frame's BT.601 weighted sum to 12 bits (`s = 4080`, a 32nd of an
//! 8-bit level). The Sobel responses of `L` then fit 16-bit lanes (at most
//! `4 * 4080`), `gx^2 + gy^2` is one multiply-add into 32 bits, and the
//! scale drops out of normal flow:
//! ```text
//! I_t = (L_j - L_{j-1}) / s,   |grad I|^2 = (gx^2 + gy^2) / (64 s^2)
//! |n|^2 = I_t^2 / |grad I|^2 = 64 (L_j - L_{j-1})^2 / (gx^2 + gy^2)
//! ```
//! and the gradient threshold is one on the integer `gx^2 + gy^2`. The change
//! is an exact integer sum, divided by `s^2` at the end.

use super::sobel::{columns_into, magnitude_sq};
use crate::image::{FrameRef, LUMA_WEIGHTS};
use crate::lanes::lane_sum;

/// Gradient magnitude under which normal flow is not measured (paper: 15/255).
pub const NORMAL_FLOW_MIN_GRADIENT: f32 = 15.0 / 255.0;

/// The scale of a planar frame's luma: `Y` 16..=235.
const PLANAR_SCALE: u16 = 219;

/// The scale of a packed frame's 12-bit luma: 255 * 16.
const PACKED_SCALE: u16 = 4080;

/// Pixels whose squared change (at most `4080^2`) is summed in 32 bits
/// before the sum is widened.
const CHANGE_BLOCK: usize = 128;

/// The integer luma of one frame and where it is valid.
#[derive(Clone, Debug, Default)]
pub(super) struct LumaPlane {
    pub width: usize,
    pub height: usize,
    /// Intensity times [`LumaPlane::scale`].
    pub luma: Vec<u16>,
    /// 1 where the pixel is valid, else 0.
    pub valid: Vec<u8>,
    pub scale: u16,
}

impl LumaPlane {
    /// Sized for `frame`, its scale set; rows are filled by [`Self::fill_row`].
    pub fn reset(&mut self, frame: &FrameRef<'_>) {
        (self.width, self.height) = (frame.width, frame.height);
        self.luma.resize(frame.width * frame.height, 0);
        self.valid.resize(frame.width * frame.height, 0);
        self.scale = if frame.format.is_planar() {
            PLANAR_SCALE
        } else {
            PACKED_SCALE
        };
    }

    /// Row `y` of `frame`'s luma, valid where `coverage` is not 0.
    #[inline(always)]
    pub fn fill_row(&mut self, frame: &FrameRef<'_>, coverage: &[u8], y: usize) {
        let w = self.width;
        let span = y * w..(y + 1) * w;
        for (v, &c) in self.valid[span.clone()]
            .iter_mut()
            .zip(&coverage[span.clone()])
        {
            *v = (c != 0) as u8;
        }
        let out = &mut self.luma[span.clone()];
        if frame.format.is_planar() {
            for (o, &l) in out.iter_mut().zip(&frame.data[span]) {
                *o = (l.clamp(16, 235) - 16) as u16;
            }
            return;
        }
        // Weights in 16.16 fixed point (they sum to 65536), to 12 bits.
        let k = LUMA_WEIGHTS.map(|w| (w * 65536.0).round() as u32);
        let c = frame.format.channels();
        for (o, p) in out.iter_mut().zip(frame.data[y * w * c..].chunks_exact(c)) {
            let sum = k[0] * p[0] as u32 + k[1] * p[1] as u32 + k[2] * p[2] as u32;
            *o = ((sum + 2048) >> 12) as u16;
        }
    }

    /// Row `y` of luma and of validity.
    #[inline(always)]
    pub fn row(&self, y: usize) -> (&[u16], &[u8]) {
        let span = y * self.width..(y + 1) * self.width;
        (&self.luma[span.clone()], &self.valid[span])
    }
}

/// `(sum of (L_cur - L_prev)^2, pixels)` over the pixels of a row valid in
/// both frames (divide by `s^2` for intensities).
#[inline(always)]
pub(super) fn change_sum(cur: (&[u16], &[u8]), prev: (&[u16], &[u8])) -> (u64, u64) {
    let (mut sum, mut n) = (0u64, 0u64);
    let (lc, vc) = cur;
    let (lp, vp) = prev;
    let w = lc.len();
    for start in (0..w).step_by(CHANGE_BLOCK) {
        let end = (start + CHANGE_BLOCK).min(w);
        // Equal-length slices: no bounds checks, so the loop vectorizes.
        let (a, b) = (&lc[start..end], &lp[start..end]);
        let (va, vb) = (&vc[start..end], &vp[start..end]);
        let (mut block, mut count) = (0u32, 0u32);
        for i in 0..end - start {
            let it = a[i] as i32 - b[i] as i32;
            let ok = (va[i] & vb[i]) as u32;
            block += ok * (it * it) as u32;
            count += ok;
        }
        sum += block as u64;
        n += count as u64;
    }
    (sum, n)
}

/// Reused rows of the normal flow.
#[derive(Clone, Debug, Default)]
pub(super) struct FlowRows {
    sums: Vec<i16>,
    diffs: Vec<i16>,
    /// `gx^2 + gy^2` where the pixel counts, else 0.
    gradient: Vec<f32>,
    /// `64 (L_cur - L_prev)^2`.
    change: Vec<f32>,
}

impl FlowRows {
    /// `(sum of |n|^2, pixels)` over the interior pixels `1..w - 1` of a row
    /// whose nine neighbours are valid (`interior`, index `x - 1`), that were
    /// valid in the previous frame and whose gradient reaches
    /// [`NORMAL_FLOW_MIN_GRADIENT`]. `rows` are the current frame's luma at,
    /// above and below the row, `prev` the previous frame's at it, both of
    /// scale `scale`.
    #[inline(always)]
    pub fn sum(
        &mut self,
        [above, at, below]: [&[u16]; 3],
        prev: (&[u16], &[u8]),
        interior: &[u8],
        scale: u16,
    ) -> (f64, u64) {
        let w = at.len();
        let n = w - 2;
        self.gradient.resize(n, 0.0);
        self.change.resize(n, 0.0);
        columns_into([above, at, below], &mut self.sums, &mut self.diffs);
        // |grad I| >= t  <=>  gx^2 + gy^2 >= 64 s^2 t^2, in integers.
        let t = NORMAL_FLOW_MIN_GRADIENT as f64 * scale as f64 * 8.0;
        let min_g2 = (t * t).ceil() as i32;
        // Equal-length slices, so the loop runs without bounds checks and
        // vectorizes: pixel `x = i + 1`.
        let (sl, sr) = (&self.sums[..n], &self.sums[2..]);
        let (dl, dc, dr) = (&self.diffs[..n], &self.diffs[1..n + 1], &self.diffs[2..]);
        let (lc, lp, vp) = (&at[1..w - 1], &prev.0[1..w - 1], &prev.1[1..w - 1]);
        let (interior, gradient, change) = (
            &interior[..n],
            &mut self.gradient[..n],
            &mut self.change[..n],
        );
        for i in 0..n {
            let g2 = magnitude_sq(sl[i], sr[i], dl[i], dc[i], dr[i]);
            let it = lc[i] as i32 - lp[i] as i32;
            let ok = interior[i] & vp[i] != 0 && g2 >= min_g2;
            gradient[i] = if ok { g2 as f32 } else { 0.0 };
            change[i] = (64 * it * it) as f32;
        }
        // Pixels that do not count have a zero gradient here.
        let (s, k) = lane_sum(&self.gradient, &self.change, &self.change, |g, c, _| {
            (c / g, g > 0.0)
        });
        (s as f64, k as u64)
    }
}
