//! Sums over `f32` slices in independent lanes.
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

/// `sum a[i]`.
#[inline(always)]
pub fn sum(a: &[f32]) -> f32 {
    lane_sum(a, a, a, |x, _, _| (x, true)).0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lane_sums_are_the_sums() {
        // Lengths below, at and past a multiple of the lanes; exact integers.
        for n in [0usize, 1, 7, 8, 9, 17, 64] {
            let a: Vec<f32> = (0..n).map(|i| i as f32).collect();
            let b: Vec<f32> = (0..n).map(|i| (i % 3) as f32).collect();
            let want: f32 = (0..n).map(|i| (i * (i % 3)) as f32).sum();
            assert_eq!(dot(&a, &b), want, "n = {n}");
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
