//! The AVX2 kernel's ghost-free rows (see [`crate::render::robust`]): the
//! plain rows' samples (`avx2.rs`), each frame weighted by its agreement with
//! the newest frame, in registers. References: `scalar::merge_row` and
//! `scalar::merge_row_gray`.

use super::avx2::{sample_gray8, sample_pair8, sample_rgb8};
use super::common::{KernelGeometry, RowCoords};
use crate::render::robust::{Deghost, FULL_WEIGHT};
use std::arch::x86_64::*;

/// The ghost-free weights of eight samples differing by `d` from the
/// reference's: [`Deghost::weight`] lane by lane (`d <= 65280`, so the scalar
/// clamp to `2^16` never acts), 16 where the reference does not cover the
/// pixel (`reference` lanes clear), 0 where the frame does not (`mask` clear).
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn weights8(deghost: Deghost, d: __m256i, reference: __m256i, mask: __m256i) -> __m256i {
    let (zero_at, slope) = deghost.constants();
    let full = _mm256_set1_epi32(FULL_WEIGHT as i32);
    let ramp = _mm256_max_epi32(
        _mm256_sub_epi32(_mm256_set1_epi32(zero_at), d),
        _mm256_setzero_si256(),
    );
    let w = _mm256_min_epi32(
        _mm256_srli_epi32::<16>(_mm256_mullo_epi32(ramp, _mm256_set1_epi32(slope))),
        full,
    );
    _mm256_and_si256(_mm256_blendv_epi8(full, w, reference), mask)
}

/// One plane's sample `v` added to its weighted sum and the weight to the
/// weights' sum, weighted by its agreement with the reference's `v0` (masks:
/// the reference's lanes, the sample's).
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn add_weighted8(
    deghost: Deghost,
    (v, v0): (__m256i, __m256i),
    (reference, mask): (__m256i, __m256i),
    (acc, acc_w): (&mut __m256i, &mut __m256i),
) {
    let w = weights8(
        deghost,
        _mm256_abs_epi32(_mm256_sub_epi32(v, v0)),
        reference,
        mask,
    );
    *acc = _mm256_add_epi32(*acc, _mm256_mullo_epi32(w, v));
    *acc_w = _mm256_add_epi32(*acc_w, w);
}

/// The ghost-free twin of `avx2::accumulate_row` (see `scalar::merge_row`, the
/// reference): for `u in 0..n8`, the last frame's samples are taken first and
/// every frame's then weighted by its agreement with them, in registers;
/// `sum_{r,g,b}`, `weight` and `count` are stored once per chunk.
///
/// # Safety
/// As `avx2::accumulate_row`.
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn merge_row(
    datas: &[&[u8]],
    g: KernelGeometry,
    coords: &[RowCoords<'_>],
    deghost: Deghost,
    n8: usize,
    sum: [&mut [u32]; 3],
    weight: &mut [u32],
    count: &mut [u32],
) {
    debug_assert!(n8 & 7 == 0 && datas.len() == coords.len() && !datas.is_empty());
    let [sum_r, sum_g, sum_b] = sum;
    debug_assert!(sum_r.len() >= n8 && sum_g.len() >= n8 && sum_b.len() >= n8);
    debug_assert!(weight.len() >= n8 && count.len() >= n8);
    let last = datas.len() - 1;
    let one = _mm256_set1_epi32(1);
    let full = _mm256_set1_epi32(FULL_WEIGHT as i32);
    let z = _mm256_setzero_si256();
    let mut u = 0;
    while u < n8 {
        let ([r0, g0, b0], m0) =
            sample_rgb8(datas[last], &g, &coords[last], u).unwrap_or(([z; 3], z));
        let w0 = _mm256_and_si256(m0, full);
        let (mut acc_r, mut acc_g, mut acc_b) = (
            _mm256_mullo_epi32(w0, r0),
            _mm256_mullo_epi32(w0, g0),
            _mm256_mullo_epi32(w0, b0),
        );
        let (mut acc_w, mut acc_n) = (w0, _mm256_and_si256(m0, one));
        for (data, coord) in datas[..last].iter().zip(coords) {
            let Some(([r, gg, b], mask)) = sample_rgb8(data, &g, coord, u) else {
                continue;
            };
            let absdiff = |a: __m256i, b: __m256i| _mm256_abs_epi32(_mm256_sub_epi32(a, b));
            let d = _mm256_max_epi32(
                _mm256_max_epi32(absdiff(r, r0), absdiff(gg, g0)),
                absdiff(b, b0),
            );
            let w = weights8(deghost, d, m0, mask);
            acc_r = _mm256_add_epi32(acc_r, _mm256_mullo_epi32(w, r));
            acc_g = _mm256_add_epi32(acc_g, _mm256_mullo_epi32(w, gg));
            acc_b = _mm256_add_epi32(acc_b, _mm256_mullo_epi32(w, b));
            acc_w = _mm256_add_epi32(acc_w, w);
            acc_n = _mm256_add_epi32(acc_n, _mm256_and_si256(mask, one));
        }
        _mm256_storeu_si256(sum_r.as_mut_ptr().add(u) as *mut __m256i, acc_r);
        _mm256_storeu_si256(sum_g.as_mut_ptr().add(u) as *mut __m256i, acc_g);
        _mm256_storeu_si256(sum_b.as_mut_ptr().add(u) as *mut __m256i, acc_b);
        _mm256_storeu_si256(weight.as_mut_ptr().add(u) as *mut __m256i, acc_w);
        _mm256_storeu_si256(count.as_mut_ptr().add(u) as *mut __m256i, acc_n);
        u += 8;
    }
}

/// The single-channel twin of [`merge_row`] (reference: `scalar::merge_row_gray`).
///
/// # Safety
/// As `avx2::accumulate_row_gray`.
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn merge_row_gray(
    datas: &[&[u8]],
    g: KernelGeometry,
    coords: &[RowCoords<'_>],
    deghost: Deghost,
    n8: usize,
    sum: &mut [u32],
    weight: &mut [u32],
    count: &mut [u32],
) {
    debug_assert!(n8 & 7 == 0 && datas.len() == coords.len() && !datas.is_empty());
    debug_assert!(sum.len() >= n8 && weight.len() >= n8 && count.len() >= n8);
    let last = datas.len() - 1;
    let one = _mm256_set1_epi32(1);
    let full = _mm256_set1_epi32(FULL_WEIGHT as i32);
    let z = _mm256_setzero_si256();
    let mut u = 0;
    while u < n8 {
        let (v0, m0) = sample_gray8(datas[last], &g, &coords[last], u).unwrap_or((z, z));
        let w0 = _mm256_and_si256(m0, full);
        let mut acc = _mm256_mullo_epi32(w0, v0);
        let (mut acc_w, mut acc_n) = (w0, _mm256_and_si256(m0, one));
        for (data, coord) in datas[..last].iter().zip(coords) {
            let Some((v, mask)) = sample_gray8(data, &g, coord, u) else {
                continue;
            };
            add_weighted8(deghost, (v, v0), (m0, mask), (&mut acc, &mut acc_w));
            acc_n = _mm256_add_epi32(acc_n, _mm256_and_si256(mask, one));
        }
        _mm256_storeu_si256(sum.as_mut_ptr().add(u) as *mut __m256i, acc);
        _mm256_storeu_si256(weight.as_mut_ptr().add(u) as *mut __m256i, acc_w);
        _mm256_storeu_si256(count.as_mut_ptr().add(u) as *mut __m256i, acc_n);
        u += 8;
    }
}

/// [`merge_row_gray`] of two planes of one geometry at once (the U and V
/// planes of 4:2:0 frames), each plane weighted by its own agreement with its
/// last frame, as two calls would; each chunk's taps are found once for both
/// (bilinear only: bicubic pairs go plane by plane, see `Kernel::pairs_bicubic`).
///
/// # Safety
/// As [`merge_row_gray`], for both planes' data.
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn merge_row_gray_pair(
    (datas_a, datas_b): (&[&[u8]], &[&[u8]]),
    g: KernelGeometry,
    coords: &[RowCoords<'_>],
    deghost: Deghost,
    n8: usize,
    (sum_a, sum_b): (&mut [u32], &mut [u32]),
    (weight_a, weight_b): (&mut [u32], &mut [u32]),
    count: &mut [u32],
) {
    debug_assert!(n8 & 7 == 0 && !coords.is_empty() && !g.cubic);
    debug_assert!(datas_a.len() == coords.len() && datas_b.len() == coords.len());
    let last = coords.len() - 1;
    let one = _mm256_set1_epi32(1);
    let full = _mm256_set1_epi32(FULL_WEIGHT as i32);
    let z = _mm256_setzero_si256();
    let mut u = 0;
    while u < n8 {
        let (ra, rb, m0) =
            sample_pair8((datas_a[last], datas_b[last]), &g, &coords[last], u).unwrap_or((z, z, z));
        let w0 = _mm256_and_si256(m0, full);
        let (mut acc_a, mut acc_b) = (_mm256_mullo_epi32(w0, ra), _mm256_mullo_epi32(w0, rb));
        let (mut acc_wa, mut acc_wb) = (w0, w0);
        let mut acc_n = _mm256_and_si256(m0, one);
        let frames = datas_a[..last].iter().zip(&datas_b[..last]).zip(coords);
        for ((a, b), coord) in frames {
            let Some((va, vb, mask)) = sample_pair8((a, b), &g, coord, u) else {
                continue;
            };
            add_weighted8(deghost, (va, ra), (m0, mask), (&mut acc_a, &mut acc_wa));
            add_weighted8(deghost, (vb, rb), (m0, mask), (&mut acc_b, &mut acc_wb));
            acc_n = _mm256_add_epi32(acc_n, _mm256_and_si256(mask, one));
        }
        for (dst, v) in [
            (&mut *sum_a, acc_a),
            (&mut *sum_b, acc_b),
            (&mut *weight_a, acc_wa),
            (&mut *weight_b, acc_wb),
            (&mut *count, acc_n),
        ] {
            _mm256_storeu_si256(dst.as_mut_ptr().add(u) as *mut __m256i, v);
        }
        u += 8;
    }
}
