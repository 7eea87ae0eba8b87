//! Finishing an output row: the kernel's sums (and the scalar reference past
//! them) into bytes and coverage.

use super::buffers::RowScratch;
use super::rows::Pass;
use crate::render::kernels::{average, Kernel};
use crate::render::robust::weighted_average;

/// Writes one interleaved output row from the kernel's sums (pixels `..n8`)
/// and the scalar path (the rest); returns the pixels every frame covers.
pub(super) fn finish_rgb_row(
    kernel: Kernel,
    pass: &Pass<'_, '_>,
    scratch: &RowScratch,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    channels: usize,
    full: u8,
) -> usize {
    let (n8, ow) = (pass.n8, cov_row.len());
    let [r, g, b] = &scratch.sums;
    let n = &scratch.count;
    let mut complete = 0usize;
    // Kernels with a finishing pass (wasm simd128) finish RGBA rows in one go.
    // SAFETY: the row sums hold `ow >= n8` values, `out_row` `4 ow` bytes.
    let finished =
        channels == 4 && n8 > 0 && unsafe { kernel.finish_row_rgba(r, g, b, n, out_row, n8) };
    if !finished {
        for (u, px) in out_row[..channels * n8]
            .chunks_exact_mut(channels)
            .enumerate()
        {
            px[0] = average(r[u], n[u]);
            px[1] = average(g[u], n[u]);
            px[2] = average(b[u], n[u]);
            if channels == 4 {
                px[3] = 255;
            }
        }
    }
    for u in 0..n8 {
        let c = n[u] as u8;
        cov_row[u] = c;
        complete += (c == full) as usize;
    }
    for u in n8..ow {
        let (mut acc, mut c) = ([0u32; 3], 0u32);
        for (f, data) in pass.datas.iter().enumerate() {
            if let Some(rgb) = pass.geom.sample(data, scratch.xs[f][u], scratch.ys[f][u]) {
                acc[0] += rgb[0];
                acc[1] += rgb[1];
                acc[2] += rgb[2];
                c += 1;
            }
        }
        let px = &mut out_row[u * channels..u * channels + channels];
        px[0] = average(acc[0], c);
        px[1] = average(acc[1], c);
        px[2] = average(acc[2], c);
        if channels == 4 {
            px[3] = 255;
        }
        cov_row[u] = c as u8;
        complete += (c as u8 == full) as usize;
    }
    complete
}

/// Writes one single-channel output row from the vector kernel's sums in
/// `scratch.sums[sums]` and the scalar reference past them (uncovered pixels
/// `fill`); returns the pixels every frame covers.
#[allow(clippy::too_many_arguments)]
pub(super) fn finish_gray_row(
    kernel: Kernel,
    pass: &Pass<'_, '_>,
    scratch: &RowScratch,
    sums: usize,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    full: u8,
    fill: u8,
) -> usize {
    let (n8, ow) = (pass.n8, cov_row.len());
    let (sum, n) = (&scratch.sums[sums][..n8], &scratch.count[..n8]);
    // SAFETY: `n8 > 0` only with a vectorized kernel from `Kernel::detect`
    // (a multiple of 8), and every row buffer holds `ow >= n8` values.
    let finished =
        unsafe { kernel.finish_row_gray(sum, n, out_row, cov_row, n8, full as u32, fill) };
    let mut complete = match finished {
        Some(complete) => complete,
        None => {
            // Separate branch-free passes over equal-length slices: each vectorizes.
            for ((o, &s), &k) in out_row[..n8].iter_mut().zip(sum).zip(n) {
                let v = average(s, k);
                *o = if k == 0 { fill } else { v };
            }
            for (c, &k) in cov_row[..n8].iter_mut().zip(n) {
                *c = k as u8;
            }
            n.iter().filter(|&&k| k == full as u32).count()
        }
    };
    for u in n8..ow {
        let (mut acc, mut c) = (0u32, 0u32);
        for (f, data) in pass.datas.iter().enumerate() {
            if let Some(s) = pass
                .geom
                .sample_gray(data, scratch.xs[f][u], scratch.ys[f][u])
            {
                acc += s;
                c += 1;
            }
        }
        out_row[u] = if c == 0 { fill } else { average(acc, c) };
        cov_row[u] = c as u8;
        complete += (c as u8 == full) as usize;
    }
    complete
}

/// Writes one interleaved output row from
/// [`Warper::merge_row`](super::Warper::merge_row)'s weighted sums (every
/// pixel); returns the pixels every frame covers.
pub(super) fn finish_merged_rgb_row(
    kernel: Kernel,
    scratch: &RowScratch,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    channels: usize,
    full: u8,
) -> usize {
    let ow = cov_row.len();
    let [r, g, b] = &scratch.sums;
    let (w, n) = (&scratch.weight, &scratch.count);
    // The RGBA finisher divides by its "count": here the weights' sum, which
    // is 0 exactly where no frame covers the pixel.
    let n4 = ow / 8 * 8;
    // SAFETY: the row sums hold `ow >= n4` values, `out_row` `4 ow` bytes.
    let finished =
        channels == 4 && n4 > 0 && unsafe { kernel.finish_row_rgba(r, g, b, w, out_row, n4) };
    let start = if finished { n4 } else { 0 };
    for (u, px) in out_row[..channels * ow]
        .chunks_exact_mut(channels)
        .enumerate()
        .skip(start)
    {
        px[0] = weighted_average(r[u], w[u], 0);
        px[1] = weighted_average(g[u], w[u], 0);
        px[2] = weighted_average(b[u], w[u], 0);
        if channels == 4 {
            px[3] = 255;
        }
    }
    write_coverage(cov_row, &n[..ow], full)
}

/// Writes one single-channel output row from
/// [`Warper::merge_row`](super::Warper::merge_row)'s weighted sums (uncovered
/// pixels `fill`) and its coverage; returns the pixels every frame covers.
/// The pixels as [`merged_gray_pixels`] writes them for the first plane.
pub(super) fn finish_merged_gray_row(
    kernel: Kernel,
    n8: usize,
    scratch: &RowScratch,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    full: u8,
    fill: u8,
) -> usize {
    merged_gray_pixels(kernel, n8, scratch, 0, out_row, cov_row, fill);
    write_coverage(cov_row, &scratch.count[..cov_row.len()], full)
}

/// Writes the pixels of one single-channel output row from
/// [`Warper::merge_row`](super::Warper::merge_row)'s weighted sums: the
/// first `n8` by the vector kernel's finisher (its `round(sum / (256 n))` is
/// `weighted_average`'s with the weights' sum for `n`, the same `f32`
/// operations), the rest here. `plane` 1 is the second plane of a pair
/// (`sums[1]`, `weight_b`), whose coverage is the first's: the finisher's
/// scribbles on `cov_row` must be written over by the first plane's
/// [`finish_merged_gray_row`], after this.
pub(super) fn merged_gray_pixels(
    kernel: Kernel,
    n8: usize,
    scratch: &RowScratch,
    plane: usize,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    fill: u8,
) {
    let ow = cov_row.len();
    let weight = if plane == 0 {
        &scratch.weight
    } else {
        &scratch.weight_b
    };
    let (sum, w) = (&scratch.sums[plane][..ow], &weight[..ow]);
    // SAFETY: `n8 > 0` only with a vectorized kernel (a multiple of 8), and
    // every row buffer holds `ow >= n8` values. Its coverage (from the
    // weights) is written again by the caller, from the counts.
    let start = match n8 {
        0 => 0,
        _ => unsafe { kernel.finish_row_gray(sum, w, out_row, cov_row, n8, 0, fill) }
            .map_or(0, |_| n8),
    };
    for ((o, &s), &k) in out_row[start..ow]
        .iter_mut()
        .zip(&sum[start..])
        .zip(&w[start..])
    {
        *o = weighted_average(s, k, fill);
    }
}

/// Writes a merged row's coverage (`counts`: frames per pixel, at most
/// [`MAX_FRAMES`](super::MAX_FRAMES)); returns the pixels all `full` frames cover.
fn write_coverage(cov_row: &mut [u8], counts: &[u32], full: u8) -> usize {
    crate::lanes::narrow_and_count(cov_row, counts, full)
}
