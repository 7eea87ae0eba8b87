//! The AVX-512 kernel's ghost-free plane rows (see [`crate::render::robust`]):
//! the plain rows' samples (`avx512.rs`), each frame weighted by its agreement
//! with the newest frame, sixteen lanes wide. Reference: `scalar::merge_row_gray`.

use super::avx512::{sample_gray16, sample_pair16, step_lanes};
use super::common::{KernelGeometry, RowCoords};
use crate::render::robust::{Deghost, FULL_WEIGHT};
use std::arch::x86_64::*;

/// The ghost-free twin of `avx512::accumulate_row_gray` (the contract of
/// `scalar::merge_row_gray`): for `u in 0..n8`, the last frame's samples are
/// taken first and every frame's then weighted by its agreement with them,
/// in registers; `sum`, `weight` and `count` are stored once per chunk. The
/// samples are `avx512::accumulate_row_gray`'s (windows or gathers, bilinear or
/// bicubic), the weights the AVX2 kernel's (`weights8`), sixteen lanes wide.
///
/// # Safety
/// As `avx512::accumulate_row_gray`, and `datas` must not be empty.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
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
    let (one, full) = (_mm512_set1_epi32(1), _mm512_set1_epi32(FULL_WEIGHT as i32));
    let mut u = 0;
    while u < n8 {
        let lanes = step_lanes(n8, u);
        let (v0, m0) = sample_gray16(datas[last], &g, &coords[last], u, lanes)
            .unwrap_or((_mm512_setzero_si512(), 0));
        let w0 = _mm512_maskz_mov_epi32(m0, full);
        let mut acc = _mm512_mullo_epi32(w0, v0);
        let (mut acc_w, mut acc_n) = (w0, _mm512_maskz_mov_epi32(m0, one));
        for (data, coord) in datas[..last].iter().zip(coords) {
            let Some((v, mask)) = sample_gray16(data, &g, coord, u, lanes) else {
                continue;
            };
            add_weighted16(deghost, (v, v0), (m0, mask), (&mut acc, &mut acc_w));
            acc_n = _mm512_mask_add_epi32(acc_n, mask, acc_n, one);
        }
        _mm512_mask_storeu_epi32(sum.as_mut_ptr().add(u) as *mut i32, lanes, acc);
        _mm512_mask_storeu_epi32(weight.as_mut_ptr().add(u) as *mut i32, lanes, acc_w);
        _mm512_mask_storeu_epi32(count.as_mut_ptr().add(u) as *mut i32, lanes, acc_n);
        u += 16;
    }
}

/// [`merge_row_gray`] of two planes of one geometry at once (the U and V
/// planes of 4:2:0 frames), each plane weighted by its own agreement with its
/// last frame, as two calls would: `sum_a`/`weight_a` and `sum_b`/`weight_b`,
/// one `count`; each chunk's taps are found once for both planes.
///
/// # Safety
/// As [`merge_row_gray`], for both planes' data.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
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
    debug_assert!(n8 & 7 == 0 && !coords.is_empty());
    debug_assert!(datas_a.len() == coords.len() && datas_b.len() == coords.len());
    let last = coords.len() - 1;
    let (one, full) = (_mm512_set1_epi32(1), _mm512_set1_epi32(FULL_WEIGHT as i32));
    let z = _mm512_setzero_si512();
    let mut u = 0;
    while u < n8 {
        let lanes = step_lanes(n8, u);
        let (ra, rb, m0) =
            sample_pair16((datas_a[last], datas_b[last]), &g, &coords[last], u, lanes)
                .unwrap_or((z, z, 0));
        let w0 = _mm512_maskz_mov_epi32(m0, full);
        let (mut acc_a, mut acc_b) = (_mm512_mullo_epi32(w0, ra), _mm512_mullo_epi32(w0, rb));
        let (mut acc_wa, mut acc_wb) = (w0, w0);
        let mut acc_n = _mm512_maskz_mov_epi32(m0, one);
        let frames = datas_a[..last].iter().zip(&datas_b[..last]).zip(coords);
        for ((a, b), coord) in frames {
            let Some((va, vb, mask)) = sample_pair16((a, b), &g, coord, u, lanes) else {
                continue;
            };
            add_weighted16(deghost, (va, ra), (m0, mask), (&mut acc_a, &mut acc_wa));
            add_weighted16(deghost, (vb, rb), (m0, mask), (&mut acc_b, &mut acc_wb));
            acc_n = _mm512_mask_add_epi32(acc_n, mask, acc_n, one);
        }
        for (dst, v) in [
            (&mut *sum_a, acc_a),
            (&mut *sum_b, acc_b),
            (&mut *weight_a, acc_wa),
            (&mut *weight_b, acc_wb),
            (&mut *count, acc_n),
        ] {
            _mm512_mask_storeu_epi32(dst.as_mut_ptr().add(u) as *mut i32, lanes, v);
        }
        u += 16;
    }
}

/// One plane's sample `v` added to its weighted sum and the weight to the
/// weights' sum, weighted by its agreement with the reference's `v0` (masks:
/// the reference's lanes, the sample's).
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn add_weighted16(
    deghost: Deghost,
    (v, v0): (__m512i, __m512i),
    (reference, mask): (__mmask16, __mmask16),
    (acc, acc_w): (&mut __m512i, &mut __m512i),
) {
    let w = weights16(
        deghost,
        _mm512_abs_epi32(_mm512_sub_epi32(v, v0)),
        reference,
        mask,
    );
    *acc = _mm512_add_epi32(*acc, _mm512_mullo_epi32(w, v));
    *acc_w = _mm512_add_epi32(*acc_w, w);
}

/// The ghost-free weights of sixteen samples differing by `d` from the
/// reference's: `Deghost::weight` lane by lane (`d <= 65280`, so the scalar
/// clamp to `2^16` never acts), full where the reference does not cover the
/// pixel (`reference` clear), 0 where the frame does not (`mask` clear).
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn weights16(
    deghost: Deghost,
    d: __m512i,
    reference: __mmask16,
    mask: __mmask16,
) -> __m512i {
    let (zero_at, slope) = deghost.constants();
    let full = _mm512_set1_epi32(FULL_WEIGHT as i32);
    let ramp = _mm512_max_epi32(
        _mm512_sub_epi32(_mm512_set1_epi32(zero_at), d),
        _mm512_setzero_si512(),
    );
    let w = _mm512_min_epi32(
        _mm512_srli_epi32::<16>(_mm512_mullo_epi32(ramp, _mm512_set1_epi32(slope))),
        full,
    );
    _mm512_maskz_mov_epi32(mask, _mm512_mask_blend_epi32(reference, full, w))
}
