//! Box downsampling: a supersampled render's `S x S` blocks averaged in integers.

/// Averages each `s x s` block of a supersampled render (`src`: `s ow x s oh`
/// pixels of `channels` bytes, `src_cov` its covering frames per pixel) into
/// one pixel of `out` (`ow x oh`) and `cov`; returns the pixels covered by
/// `full` frames.
///
/// A pixel's coverage is its block's least (it counts as covered by a frame
/// only where every sample is); its value the rounded mean (`(sum + n / 2) /
/// n`, half up as the kernels' averages) of the samples that some frame
/// covers, so a pixel on the edge of the covered area is not darkened by
/// the fill of its uncovered samples; with none covered, of all samples
/// (each the fill). Integers only: the same bytes whatever the kernel.
#[allow(clippy::too_many_arguments)]
pub(super) fn box_down(
    src: &[u8],
    src_cov: &[u8],
    s: usize,
    channels: usize,
    (ow, oh): (usize, usize),
    out: &mut [u8],
    cov: &mut [u8],
    full: u8,
) -> usize {
    let rw = s * ow;
    let all = (s * s) as u32;
    let row = |v: usize, out_row: &mut [u8], cov_row: &mut [u8]| {
        let mut complete = 0;
        for (u, (px, c_out)) in out_row
            .chunks_exact_mut(channels)
            .zip(cov_row.iter_mut())
            .enumerate()
        {
            let (mut least, mut n) = (u8::MAX, 0u32);
            let (mut sum_cov, mut sum_all) = ([0u32; 4], [0u32; 4]);
            for l in 0..s {
                let first = (s * v + l) * rw + s * u;
                for i in first..first + s {
                    let c = src_cov[i];
                    least = least.min(c);
                    let covered = (c > 0) as u32;
                    n += covered;
                    for ch in 0..channels {
                        let x = src[i * channels + ch] as u32;
                        sum_all[ch] += x;
                        sum_cov[ch] += x * covered;
                    }
                }
            }
            let (sum, n) = if n > 0 { (sum_cov, n) } else { (sum_all, all) };
            for (o, &t) in px.iter_mut().zip(&sum) {
                *o = ((t + n / 2) / n) as u8;
            }
            *c_out = least;
            complete += (least == full) as usize;
        }
        complete
    };
    by_rows(
        &mut out[..ow * oh * channels],
        &mut cov[..ow * oh],
        ow,
        channels,
        row,
    )
}

/// Averages each `s x s` block of a supersampled saccade slot (`values`:
/// 8.8 fixed-point samples, `channels` per pixel; `covered`: 0 or 1 per
/// pixel; `s ow x s oh` pixels) into one pixel of `out_values` / `out_covered`
/// (`ow x oh`): covered only where every sample is (the slot is added to the
/// running sum as a whole frame, and a partly covered pixel would mix in the
/// uncovered samples' zeros), with the rounded mean of its samples; 0 elsewhere.
pub(super) fn box_down_slot(
    values: &[u16],
    covered: &[u8],
    s: usize,
    channels: usize,
    (ow, oh): (usize, usize),
    out_values: &mut [u16],
    out_covered: &mut [u8],
) {
    let rw = s * ow;
    let n = (s * s) as u32;
    let row = |v: usize, out_row: &mut [u16], cov_row: &mut [u8]| {
        for (u, (px, c_out)) in out_row
            .chunks_exact_mut(channels)
            .zip(cov_row.iter_mut())
            .enumerate()
        {
            let mut all = true;
            let mut sum = [0u32; 3];
            for l in 0..s {
                let first = (s * v + l) * rw + s * u;
                for i in first..first + s {
                    all &= covered[i] != 0;
                    for (ch, acc) in sum.iter_mut().enumerate().take(channels) {
                        *acc += values[i * channels + ch] as u32;
                    }
                }
            }
            for (o, &t) in px.iter_mut().zip(&sum) {
                *o = if all { ((t + n / 2) / n) as u16 } else { 0 };
            }
            *c_out = all as u8;
        }
        0
    };
    let (values, covered) = (
        &mut out_values[..ow * oh * channels],
        &mut out_covered[..ow * oh],
    );
    by_rows(values, covered, ow, channels, row);
}

/// Calls `row(v, out_row, coverage_row)` for the rows of an `ow`-wide image
/// of `channels` values per pixel and its coverage, and sums what it returns:
/// on the rayon pool with the `parallel` feature and more than one thread.
pub(super) fn by_rows<T: Send>(
    out: &mut [T],
    coverage: &mut [u8],
    ow: usize,
    channels: usize,
    row: impl Fn(usize, &mut [T], &mut [u8]) -> usize + Sync,
) -> usize {
    if ow == 0 || channels == 0 {
        return 0;
    }
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        if rayon::current_num_threads() > 1 {
            return out
                .par_chunks_mut(ow * channels)
                .zip(coverage.par_chunks_mut(ow))
                .enumerate()
                .map(|(v, (o, c))| row(v, o, c))
                .sum();
        }
    }
    out.chunks_mut(ow * channels)
        .zip(coverage.chunks_mut(ow))
        .enumerate()
        .map(|(v, (o, c))| row(v, o, c))
        .sum()
}
