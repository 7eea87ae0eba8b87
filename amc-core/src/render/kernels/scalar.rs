//! The scalar reference: the bilinear 8.8 fixed-point sampler every kernel must
//! match bit for bit, used directly for the pixels the vector kernels leave
//! (row tails, unpadded frames, CPUs without them), and [`accumulate_row`], the
//! per-pixel statement of the row kernels' contract.

use super::{RowCoords, EDGE_TOLERANCE};
use crate::image::FrameRef;

/// Frame geometry, hoisted out of sampling loops.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Geometry {
    /// Bytes per pixel (3 or 4).
    pub(crate) channels: usize,
    /// Bytes per row.
    pub(crate) stride: usize,
    /// Largest column of a top-left tap (`width - 2`).
    pub(crate) max_x0: usize,
    /// Largest row of a top-left tap (`height - 2`).
    pub(crate) max_y0: usize,
    /// Largest sample x, pixels (`width - 1`).
    pub(crate) max_x: f32,
    /// Largest sample y, pixels (`height - 1`).
    pub(crate) max_y: f32,
}

impl Geometry {
    /// The geometry of `frame` (frames narrower or lower than 2 pixels are treated as 2).
    pub(crate) fn of(frame: &FrameRef<'_>) -> Self {
        let (sw, sh) = (frame.width.max(2), frame.height.max(2));
        Self {
            channels: frame.format.channels(),
            stride: frame.stride(),
            max_x0: sw - 2,
            max_y0: sh - 2,
            max_x: (sw - 1) as f32,
            max_y: (sh - 1) as f32,
        }
    }

    /// Bilinear 8.8 fixed-point RGB sample of `data` at `(sx, sy)`; `None`
    /// outside the frame.
    #[inline(always)]
    pub(crate) fn sample(&self, data: &[u8], sx: f32, sy: f32) -> Option<[u32; 3]> {
        let tol = EDGE_TOLERANCE;
        if !(sx >= -tol && sy >= -tol && sx <= self.max_x + tol && sy <= self.max_y + tol) {
            return None;
        }
        // Points within the tolerance outside the frame sample its edge.
        let (sx, sy) = (sx.max(0.0).min(self.max_x), sy.max(0.0).min(self.max_y));
        let c = self.channels;
        let x0 = (sx as usize).min(self.max_x0);
        let y0 = (sy as usize).min(self.max_y0);
        let ax = ((sx - x0 as f32) * 256.0 + 0.5) as u32;
        let ay = ((sy - y0 as f32) * 256.0 + 0.5) as u32;
        let (bx, by) = (256 - ax, 256 - ay);
        let i = y0 * self.stride + x0 * c;
        // One slice covering both rows: a single bounds check for all 12 taps.
        let taps = data.get(i..i + self.stride + c + 3)?;
        let s = self.stride;
        let mut out = [0u32; 3];
        for ch in 0..3 {
            let top = taps[ch] as u32 * bx + taps[c + ch] as u32 * ax;
            let bot = taps[s + ch] as u32 * bx + taps[s + c + ch] as u32 * ax;
            out[ch] = (top * by + bot * ay + 128) >> 8;
        }
        Some(out)
    }
}

/// The row kernels' contract, pixel by pixel: for `u in 0..n`,
/// `acc_{r,g,b}[u] = sum_f sample_f(coords[f] at u)` and `count[u]` = frames whose
/// coordinate lies inside the frame.
#[allow(clippy::too_many_arguments)]
pub(crate) fn accumulate_row(
    datas: &[&[u8]],
    geom: &Geometry,
    coords: &[RowCoords<'_>],
    n: usize,
    acc_r: &mut [u32],
    acc_g: &mut [u32],
    acc_b: &mut [u32],
    count: &mut [u32],
) {
    for u in 0..n {
        let (mut sum, mut covered) = ([0u32; 3], 0u32);
        for (data, coord) in datas.iter().zip(coords) {
            let (sx, sy) = coord.at(u);
            if let Some(rgb) = geom.sample(data, sx, sy) {
                sum[0] += rgb[0];
                sum[1] += rgb[1];
                sum[2] += rgb[2];
                covered += 1;
            }
        }
        acc_r[u] = sum[0];
        acc_g[u] = sum[1];
        acc_b[u] = sum[2];
        count[u] = covered;
    }
}
