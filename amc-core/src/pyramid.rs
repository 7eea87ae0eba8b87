//! Grayscale preparation and image pyramids for the tracker.
//!
//! Invalid pixels (outside the lens's image, or outside the source frame after
//! undistortion) are stored as `NaN`. Every operation propagates `NaN`, so a
//! pixel whose neighbourhood touches invalid data is itself invalid, and the
//! tracker never has to consult a separate mask.

use crate::image::{FrameRef, GrayImage, PixelFormat, LUMA_WEIGHTS};

/// Box-downscales a colour frame by an integer factor `s` while converting it to
/// `[0, 1]` luma. Output pixel `(u, v)` averages source pixels
/// `[s u, s u + s) x [s v, s v + s)`, so its centre lies at source coordinate
/// `s u + (s - 1) / 2` (see [`crate::frontend::box_downscaled`]).
pub fn luma_box_downscale_into(src: &FrameRef<'_>, s: usize, dst: &mut GrayImage) {
    let s = s.max(1);
    let (w, h) = (src.width / s, src.height / s);
    dst.resize(w, h);
    if src.format == PixelFormat::Yuv420p {
        y_box_downscale_into(src, s, dst);
        return;
    }
    let c = src.format.channels();
    let stride = src.stride();
    let norm = 1.0 / (255.0 * (s * s) as f32);
    let k = [
        LUMA_WEIGHTS[0] * norm,
        LUMA_WEIGHTS[1] * norm,
        LUMA_WEIGHTS[2] * norm,
    ];
    if s == 1 {
        // Indexed (not chunks_exact) so LLVM vectorizes the stride-3/4 loads.
        let n = dst.data.len().min(src.data.len() / c);
        let (d, out) = (&src.data[..n * c], &mut dst.data[..n]);
        if c == 3 {
            for i in 0..n {
                out[i] = k[0] * d[3 * i] as f32
                    + k[1] * d[3 * i + 1] as f32
                    + k[2] * d[3 * i + 2] as f32;
            }
        } else {
            for i in 0..n {
                out[i] = k[0] * d[4 * i] as f32
                    + k[1] * d[4 * i + 1] as f32
                    + k[2] * d[4 * i + 2] as f32;
            }
        }
        return;
    }
    // Sum each s x s block's channels per output pixel (no scratch buffer, so
    // no allocation per frame); the usual factors and pixel sizes with both
    // known to the compiler, which then unrolls the block (the generic loop
    // took 1.7 ms a 720p frame at 4, the `--fov auto` pass's preparation).
    let rows = (src.data, stride, k);
    match (s, c) {
        (2, 3) => rgb_box_downscale::<2, 3>(rows, dst),
        (3, 3) => rgb_box_downscale::<3, 3>(rows, dst),
        (4, 3) => rgb_box_downscale::<4, 3>(rows, dst),
        (6, 3) => rgb_box_downscale::<6, 3>(rows, dst),
        (8, 3) => rgb_box_downscale::<8, 3>(rows, dst),
        (2, 4) => rgb_box_downscale::<2, 4>(rows, dst),
        (4, 4) => rgb_box_downscale::<4, 4>(rows, dst),
        _ => {
            for v in 0..h {
                let out = &mut dst.data[v * w..(v + 1) * w];
                for (u, o) in out.iter_mut().enumerate() {
                    let mut a = [0u32; 3];
                    for dy in 0..s {
                        let start = (v * s + dy) * stride + u * s * c;
                        for px in src.data[start..start + s * c].chunks_exact(c) {
                            a[0] += px[0] as u32;
                            a[1] += px[1] as u32;
                            a[2] += px[2] as u32;
                        }
                    }
                    *o = k[0] * a[0] as f32 + k[1] * a[1] as f32 + k[2] * a[2] as f32;
                }
            }
        }
    }
}

/// [`luma_box_downscale_into`] of packed pixels of `C` bytes by `S` (`dst`
/// already sized): each block's channel sums, then the same weighted sum.
#[inline(always)]
fn rgb_box_downscale<const S: usize, const C: usize>(
    (data, stride, k): (&[u8], usize, [f32; 3]),
    dst: &mut GrayImage,
) {
    let w = dst.width;
    if w == 0 {
        return;
    }
    for (v, out) in dst.data.chunks_exact_mut(w).enumerate() {
        let rows: [&[u8]; S] = std::array::from_fn(|dy| &data[(v * S + dy) * stride..]);
        for (u, o) in out.iter_mut().enumerate() {
            let mut a = [0u32; 3];
            for row in rows {
                let (px, _) = row[u * S * C..(u + 1) * S * C].as_chunks::<C>();
                for p in px {
                    a[0] += p[0] as u32;
                    a[1] += p[1] as u32;
                    a[2] += p[2] as u32;
                }
            }
            *o = k[0] * a[0] as f32 + k[1] * a[1] as f32 + k[2] * a[2] as f32;
        }
    }
}

/// The Y plane's part of [`luma_box_downscale_into`]: block means of Y mapped
/// to `[0, 1]` as [`crate::image::y_to_unit`] does (`dst` already sized).
fn y_box_downscale_into(src: &FrameRef<'_>, s: usize, dst: &mut GrayImage) {
    let (y, _, _) = src.yuv_planes();
    let (w, sw) = (dst.width, src.width);
    let norm = 1.0 / (219.0 * (s * s) as f32);
    let bias = 16.0 * (s * s) as f32;
    if s == 1 {
        for (o, &v) in dst.data.iter_mut().zip(y) {
            *o = (v as f32 - bias) * norm;
        }
        return;
    }
    // Block sums in the output row itself (integers below 2^24: exact in f32),
    // so nothing is allocated per frame.
    for v in 0..dst.height {
        let out = &mut dst.data[v * w..(v + 1) * w];
        out.fill(0.0);
        for dy in 0..s {
            let row = &y[(v * s + dy) * sw..(v * s + dy + 1) * sw];
            // The usual factors with the block width known to the compiler,
            // which then vectorizes the loop (a third of the time at 4).
            match s {
                2 => add_block_sums::<2>(out, row),
                3 => add_block_sums::<3>(out, row),
                4 => add_block_sums::<4>(out, row),
                6 => add_block_sums::<6>(out, row),
                8 => add_block_sums::<8>(out, row),
                _ => {
                    for (acc, block) in out.iter_mut().zip(row.chunks_exact(s)) {
                        *acc += block.iter().map(|&b| b as u32).sum::<u32>() as f32;
                    }
                }
            }
        }
        for o in out.iter_mut() {
            *o = (*o - bias) * norm;
        }
    }
}

/// `out[u] += sum(row[S u..S u + S])` for every `u` of `out` that `row` covers.
#[inline(always)]
fn add_block_sums<const S: usize>(out: &mut [f32], row: &[u8]) {
    let (blocks, _) = row.as_chunks::<S>();
    for (acc, block) in out.iter_mut().zip(blocks) {
        *acc += block.iter().map(|&b| b as u32).sum::<u32>() as f32;
    }
}

/// Halves an image with a 2x2 box filter (centre of output `(u, v)` at input
/// `(2u + 0.5, 2v + 0.5)`). `NaN` propagates.
pub fn half_into(src: &GrayImage, dst: &mut GrayImage) {
    let (w, h) = (src.width / 2, src.height / 2);
    dst.resize(w, h);
    for v in 0..h {
        let r0 = &src.data[(2 * v) * src.width..];
        let r1 = &src.data[(2 * v + 1) * src.width..];
        let out = &mut dst.data[v * w..(v + 1) * w];
        for (u, o) in out.iter_mut().enumerate() {
            *o = 0.25 * (r0[2 * u] + r0[2 * u + 1] + r1[2 * u] + r1[2 * u + 1]);
        }
    }
}

/// A coarse-to-fine image pyramid: `levels[0]` is the finest.
#[derive(Clone, Debug, Default)]
pub struct Pyramid {
    /// Level `l` has half the size of level `l - 1` (2x2 box average).
    pub levels: Vec<GrayImage>,
}

/// Smallest side (pixels) a pyramid level may have: below this a level holds
/// too few pixels to constrain three rotation parameters reliably.
pub const MIN_LEVEL_SIDE: usize = 12;

impl Pyramid {
    /// Number of levels that fit for a base image of this size, capped at `max_levels`.
    pub fn level_count(width: usize, height: usize, max_levels: usize) -> usize {
        let mut n = 1;
        let (mut w, mut h) = (width, height);
        while n < max_levels && w / 2 >= MIN_LEVEL_SIDE && h / 2 >= MIN_LEVEL_SIDE {
            w /= 2;
            h /= 2;
            n += 1;
        }
        n
    }

    /// Rebuilds levels `1..n` from `levels[0]` (which the caller filled), reusing buffers.
    pub fn rebuild(&mut self, n_levels: usize) {
        let n = n_levels.max(1);
        self.levels.resize_with(n, GrayImage::default);
        for l in 1..n {
            let (fine, coarse) = self.levels.split_at_mut(l);
            half_into(&fine[l - 1], &mut coarse[0]);
        }
    }
}

/// Maps tracking-camera pixels to source pixels for undistortion: a dense table
/// of source coordinates (`NaN` where the lens has no image).
#[derive(Clone, Debug, Default)]
pub struct RemapTable {
    /// Width of the tracking image, pixels.
    pub width: usize,
    /// Height of the tracking image, pixels.
    pub height: usize,
    /// Source pixel `(x, y)` of each tracking pixel, row by row (`NaN`: none).
    pub coords: Vec<[f32; 2]>,
}

/// Bilinear remap of `src` through `table` into `dst` (`NaN` outside `src`).
pub fn remap_into(src: &GrayImage, table: &RemapTable, dst: &mut GrayImage) {
    dst.resize(table.width, table.height);
    for (o, c) in dst.data.iter_mut().zip(&table.coords) {
        *o = src.sample(c[0], c[1]).unwrap_or(f32::NAN);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::{Frame, PixelFormat};

    #[test]
    fn downscale_averages_blocks() {
        let mut f = Frame::new(4, 2, PixelFormat::Rgb8);
        for (i, px) in f.data.chunks_exact_mut(3).enumerate() {
            px.fill((i * 10) as u8);
        }
        let mut g = GrayImage::default();
        luma_box_downscale_into(&f.as_ref(), 2, &mut g);
        assert_eq!((g.width, g.height), (2, 1));
        // Block 0 holds values 0, 10, 40, 50 -> mean 25.
        assert!((g.data[0] - 25.0 / 255.0).abs() < 1e-5);
        assert!((g.data[1] - 45.0 / 255.0).abs() < 1e-5);
    }

    /// Every factor and pixel size, the unrolled paths and the generic one,
    /// give the reference's block sums and weights bit for bit (widths and
    /// heights that are no multiple of the factor included).
    #[test]
    fn packed_downscales_match_the_reference_bit_for_bit() {
        for format in [PixelFormat::Rgb8, PixelFormat::Rgba8] {
            let c = format.channels();
            // Frames narrower than a block too (no output column).
            let sizes =
                (1..=9usize).flat_map(|s| [(s, 7 * s + s / 2 + 1, 3 * s + 2), (s, s - 1, 2 * s)]);
            for (s, w, h) in sizes.filter(|&(_, w, _)| w > 0) {
                let mut f = Frame::new(w, h, format);
                for (i, b) in f.data.iter_mut().enumerate() {
                    *b = (i.wrapping_mul(2654435761) >> 7) as u8;
                }
                let mut got = GrayImage::default();
                luma_box_downscale_into(&f.as_ref(), s, &mut got);
                let norm = 1.0 / (255.0 * (s * s) as f32);
                let k = LUMA_WEIGHTS.map(|x| x * norm);
                assert_eq!((got.width, got.height), (w / s, h / s));
                for v in 0..h / s {
                    for u in 0..w / s {
                        let mut a = [0u32; 3];
                        for dy in 0..s {
                            for dx in 0..s {
                                let at = ((v * s + dy) * w + u * s + dx) * c;
                                for (ch, sum) in a.iter_mut().enumerate() {
                                    *sum += f.data[at + ch] as u32;
                                }
                            }
                        }
                        let want = k[0] * a[0] as f32 + k[1] * a[1] as f32 + k[2] * a[2] as f32;
                        let at = v * (w / s) + u;
                        assert_eq!(
                            got.data[at].to_bits(),
                            want.to_bits(),
                            "{format:?} s {s} ({u}, {v})"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn pyramid_levels_and_nan_propagation() {
        let mut p = Pyramid::default();
        p.levels.push(GrayImage::new(64, 40));
        p.levels[0].data[0] = f32::NAN;
        let n = Pyramid::level_count(64, 40, 8);
        assert_eq!(n, 2);
        p.rebuild(n);
        assert_eq!((p.levels[1].width, p.levels[1].height), (32, 20));
        assert!(p.levels[1].data[0].is_nan());
        assert_eq!(p.levels[1].data[1], 0.0);
    }
}
