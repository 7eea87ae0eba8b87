//! Sums over `f32` slices in independent lanes, and byte counts in byte lanes.
//!
//! A running `f32` sum is one serial chain of additions, which the compiler
//! may not reorder (float addition is not associative), so such a loop runs at
//! one addition per latency and never vectorizes. Summing into [`LANES`]
//! separate accumulators and adding them at the end vectorizes; the result
//! differs from the serial sum by rounding only. The tracker's rolling-shutter
//! moments and the metrics' per-pixel sums were each their module's hottest
//! loop before they were summed this way.

/// Independent accumulators: one AVX register of `f32`, or two SSE ones.
pub const LANES: usize = 8;

/// Sum of `term(a[i], b[i], c[i]).0` over the `i` where its `.1` holds, and
/// how many those are (over the shortest of `a`, `b`, `c`).
#[inline(always)]
pub fn lane_sum(
    a: &[f32],
    b: &[f32],
    c: &[f32],
    term: impl Fn(f32, f32, f32) -> (f32, bool),
) -> (f32, u32) {
    let n = a.len().min(b.len()).min(c.len());
    let (a, b, c) = (&a[..n], &b[..n], &c[..n]);
    let (mut s, mut k) = ([0f32; LANES], [0u32; LANES]);
    let n8 = n / LANES * LANES;
    for ((xa, xb), xc) in a[..n8]
        .chunks_exact(LANES)
        .zip(b[..n8].chunks_exact(LANES))
        .zip(c[..n8].chunks_exact(LANES))
    {
        for l in 0..LANES {
            let (v, ok) = term(xa[l], xb[l], xc[l]);
            s[l] += if ok { v } else { 0.0 };
            k[l] += ok as u32;
        }
    }
    for i in n8..n {
        let (v, ok) = term(a[i], b[i], c[i]);
        s[0] += if ok { v } else { 0.0 };
        k[0] += ok as u32;
    }
    (s.iter().sum(), k.iter().sum())
}

/// `sum a[i] b[i]` over the shorter of the two.
#[inline(always)]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    lane_sum(a, b, b, |x, y, _| (x * y, true)).0
}

/// Adds `a[i] b[i]` (over the shorter of the two) into the lane
/// accumulators `acc`, lane `i % LANES` (a tail past the last whole group
/// into lane 0), without adding the lanes up: a sum spread over many short
/// slices adds its lanes once at the end ([`lanes_total`]). Reducing the
/// lanes after every slice of 64 was a serial chain of seven additions per
/// sum, and the tracker's rolling-shutter moments take 12 to 63 sums per
/// slice.
#[inline(always)]
pub fn dot_into(a: &[f32], b: &[f32], acc: &mut [f32; LANES]) {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let n8 = n / LANES * LANES;
    for (xa, xb) in a[..n8].chunks_exact(LANES).zip(b[..n8].chunks_exact(LANES)) {
        for l in 0..LANES {
            acc[l] += xa[l] * xb[l];
        }
    }
    for i in n8..n {
        acc[0] += a[i] * b[i];
    }
}

/// Adds `a[i]` into the lane accumulators `acc` as [`dot_into`] adds
/// products.
#[inline(always)]
pub fn sum_into(a: &[f32], acc: &mut [f32; LANES]) {
    let n8 = a.len() / LANES * LANES;
    for xa in a[..n8].chunks_exact(LANES) {
        for l in 0..LANES {
            acc[l] += xa[l];
        }
    }
    for x in &a[n8..] {
        acc[0] += x;
    }
}

/// The lanes of [`dot_into`]'s and [`sum_into`]'s accumulators added up,
/// in `f64`.
#[inline(always)]
pub fn lanes_total(acc: &[f32; LANES]) -> f64 {
    acc.iter().map(|&x| x as f64).sum()
}

/// `sum a[i]`.
#[inline(always)]
pub fn sum(a: &[f32]) -> f32 {
    lane_sum(a, a, a, |x, _, _| (x, true)).0
}

/// Copies `src` into `dst` as bytes (`src[i] as u8`, over the shorter of
/// the two) and counts the copies equal to `byte`.
///
/// A count kept in a `usize` vectorizes two bytes at a time at the baseline
/// instruction set (one 64-bit lane each); kept in a byte over runs of 255,
/// sixteen. Both coverage passes of a render ran at the first rate and were
/// 7% of a 720p run.
#[inline]
pub fn narrow_and_count(dst: &mut [u8], src: &[u32], byte: u8) -> usize {
    dst.chunks_mut(255)
        .zip(src.chunks(255))
        .map(|(dst, src)| {
            let mut run = 0u8;
            for (d, &s) in dst.iter_mut().zip(src) {
                *d = s as u8;
                run += (*d == byte) as u8;
            }
            run as usize
        })
        .sum()
}

/// How many bytes of `a` equal `byte` (counted as [`narrow_and_count`] does).
#[inline]
pub fn count_byte(a: &[u8], byte: u8) -> usize {
    a.chunks(255)
        .map(|run| run.iter().fold(0u8, |n, &x| n + (x == byte) as u8) as usize)
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_counts_are_the_counts() {
        // Runs below, at and past 255, so that a run's byte count is full.
        for n in [0usize, 1, 254, 255, 256, 511, 1000] {
            let src: Vec<u32> = (0..n as u32).map(|i| (i * 7) % 300).collect();
            let mut dst = vec![9u8; n + 3];
            for byte in [0u8, 6, 44] {
                let want = src.iter().filter(|&&s| s as u8 == byte).count();
                assert_eq!(narrow_and_count(&mut dst, &src, byte), want, "n = {n}");
                assert!(dst[..n].iter().zip(&src).all(|(&d, &s)| d == s as u8));
                assert_eq!(dst[n..], [9, 9, 9]);
                assert_eq!(count_byte(&dst[..n], byte), want, "n = {n}");
            }
            let all = vec![3u8; n];
            assert_eq!(count_byte(&all, 3), n);
        }
    }

    #[test]
    fn lane_sums_are_the_sums() {
        // Lengths below, at and past a multiple of the lanes; exact integers.
        for n in [0usize, 1, 7, 8, 9, 17, 64] {
            let a: Vec<f32> = (0..n).map(|i| i as f32).collect();
            let b: Vec<f32> = (0..n).map(|i| (i % 3) as f32).collect();
            let want: f32 = (0..n).map(|i| (i * (i % 3)) as f32).sum();
            assert_eq!(dot(&a, &b), want, "n = {n}");
            let mut acc = [0f32; LANES];
            dot_into(&a[..n / 2], &b[..n / 2], &mut acc);
            dot_into(&a[n / 2..], &b[n / 2..], &mut acc);
            assert_eq!(lanes_total(&acc), want as f64, "n = {n}");
            let mut acc = [0f32; LANES];
            sum_into(&b[..n / 3], &mut acc);
            sum_into(&b[n / 3..], &mut acc);
            assert_eq!(lanes_total(&acc), sum(&b) as f64, "n = {n}");
            assert_eq!(sum(&b), (0..n).map(|i| (i % 3) as f32).sum::<f32>());
            let odd = lane_sum(&a, &a, &a, |x, _, _| (x, x as usize % 2 == 1));
            assert_eq!(
                odd,
                (
                    (0..n).filter(|i| i % 2 == 1).sum::<usize>() as f32,
                    (n / 2) as u32
                )
            );
        }
    }
}
