//! The x86-64 AVX-512 plane kernel (AVX-512 F, BW, VL and VBMI, chosen at run
//! time): the single-channel rows of planar frames, sixteen output pixels at
//! a time, bit-exact with the scalar reference in `scalar.rs`.
//!
//! Why it is faster than the AVX2 kernel: not the wider lanes so much as the
//! taps. Under a rotation, sixteen neighbouring output pixels land on a short
//! run of source pixels spread over at most two rows (three rows of taps), so
//! instead of gathering every tap the kernel loads a 64-byte window of each
//! of those rows and picks every lane's pair of horizontal taps out of it with
//! one byte permute (`vpermb`). A chunk whose taps spread wider (a strong
//! zoom-out, a steep roll, a window past the plane's end) takes two 16-lane
//! gathers instead, as the AVX2 kernel does. Both fetch the same bytes, and
//! the arithmetic after them is exact integer arithmetic equal to the
//! reference's, so the choice never changes a result. Bicubic planes take
//! each lane's four taps of four rows the same way, from windows of five
//! rows (`sample_cubic16`). The ghost-free average of planes
//! (`merge_row_gray`) samples the same way.

pub(super) use super::avx512_merge::{merge_row_gray, merge_row_gray_pair};
use super::common::{falls, KernelGeometry, RowCoords, EDGE_TOLERANCE};

use std::arch::x86_64::*;

/// Largest offset of a lane's left tap inside the 64-byte window: its right
/// neighbour is the window's last byte.
const WINDOW_SPAN: i32 = 62;

/// Columns the window starts left of lane 0's left tap: later lanes may
/// wander left of it (a grid-interpolated row is monotonic only cell by
/// cell), and 8 columns of slack still leave 54 for the run.
const WINDOW_SLACK: i32 = 8;

/// Bytes 0 and 2 of every 32-bit lane: where the permute writes a lane's left
/// and right tap (the other bytes are zeroed, leaving two 16-bit words).
const PAIR_BYTES: __mmask64 = 0x5555_5555_5555_5555;

/// The lanes of the step at pixel `u` of `n8` (a multiple of 8): all sixteen,
/// or the lower eight in a last step of eight.
#[inline(always)]
pub(super) fn step_lanes(n8: usize, u: usize) -> __mmask16 {
    if n8 - u >= 16 {
        0xFFFF
    } else {
        0x00FF
    }
}

/// Whether this CPU can run this kernel.
pub(super) fn available() -> bool {
    is_x86_feature_detected!("avx512f")
        && is_x86_feature_detected!("avx512bw")
        && is_x86_feature_detected!("avx512vl")
        && is_x86_feature_detected!("avx512vbmi")
}

/// For `u in 0..n8` (a multiple of 8), `acc[u] = sum_f sample_f(coords[f] at u)`
/// and `count[u]` = frames whose coordinate lies inside the plane: the
/// contract of `scalar::accumulate_row_gray`. Sixteen lanes per step; a last
/// step of eight runs with the upper lanes masked off.
///
/// # Safety
/// The CPU must support AVX-512 F, BW, VL and VBMI ([`available`]); every
/// `datas[f]` must hold the whole plane plus 2 readable bytes
/// ([`super::FRAME_PADDING`] covers it); coordinate tables and the outputs
/// must have at least `n8` elements.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
pub(super) unsafe fn accumulate_row_gray(
    datas: &[&[u8]],
    g: KernelGeometry,
    coords: &[RowCoords<'_>],
    n8: usize,
    acc: &mut [u32],
    count: &mut [u32],
) {
    debug_assert!(n8 & 7 == 0 && datas.len() == coords.len());
    debug_assert!(acc.len() >= n8 && count.len() >= n8);
    let one = _mm512_set1_epi32(1);
    let mut u = 0;
    while u < n8 {
        let lanes = step_lanes(n8, u);
        let (mut sum, mut sum_n) = (_mm512_setzero_si512(), _mm512_setzero_si512());
        for (data, coord) in datas.iter().zip(coords) {
            let Some((v, mask)) = sample_gray16(data, &g, coord, u, lanes) else {
                continue;
            };
            sum = _mm512_add_epi32(sum, v);
            sum_n = _mm512_mask_add_epi32(sum_n, mask, sum_n, one);
        }
        _mm512_mask_storeu_epi32(acc.as_mut_ptr().add(u) as *mut i32, lanes, sum);
        _mm512_mask_storeu_epi32(count.as_mut_ptr().add(u) as *mut i32, lanes, sum_n);
        u += 16;
    }
}

/// [`accumulate_row_gray`] of two planes of one geometry at once (the U and
/// V planes of 4:2:0 frames): `acc_a` and `acc_b` from `datas_a` and
/// `datas_b`, one `count`. Each chunk's coordinates, taps and window (and
/// bicubic weights) are found once for both planes; only the loads and the
/// arithmetic after them are done twice.
///
/// # Safety
/// As [`accumulate_row_gray`], for both planes' data.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn accumulate_row_gray_pair(
    datas_a: &[&[u8]],
    datas_b: &[&[u8]],
    g: KernelGeometry,
    coords: &[RowCoords<'_>],
    n8: usize,
    acc_a: &mut [u32],
    acc_b: &mut [u32],
    count: &mut [u32],
) {
    debug_assert!(n8 & 7 == 0 && datas_a.len() == coords.len() && datas_b.len() == coords.len());
    debug_assert!(acc_a.len() >= n8 && acc_b.len() >= n8 && count.len() >= n8);
    let one = _mm512_set1_epi32(1);
    let mut u = 0;
    while u < n8 {
        let lanes = step_lanes(n8, u);
        let (mut sum_a, mut sum_b, mut sum_n) = (
            _mm512_setzero_si512(),
            _mm512_setzero_si512(),
            _mm512_setzero_si512(),
        );
        for ((a, b), coord) in datas_a.iter().zip(datas_b).zip(coords) {
            let Some((va, vb, mask)) = sample_pair16((a, b), &g, coord, u, lanes) else {
                continue;
            };
            sum_a = _mm512_add_epi32(sum_a, va);
            sum_b = _mm512_add_epi32(sum_b, vb);
            sum_n = _mm512_mask_add_epi32(sum_n, mask, sum_n, one);
        }
        _mm512_mask_storeu_epi32(acc_a.as_mut_ptr().add(u) as *mut i32, lanes, sum_a);
        _mm512_mask_storeu_epi32(acc_b.as_mut_ptr().add(u) as *mut i32, lanes, sum_b);
        _mm512_mask_storeu_epi32(count.as_mut_ptr().add(u) as *mut i32, lanes, sum_n);
        u += 16;
    }
}

/// The samples of output pixels `u..u + 16` in two planes of one geometry,
/// their taps found once (windows or gathers, bilinear or bicubic, as
/// [`sample_gray16`] takes them per plane), and the lanes inside the planes;
/// `None` where no lane is.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
pub(super) unsafe fn sample_pair16(
    (a, b): (&[u8], &[u8]),
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    lanes: __mmask16,
) -> Option<(__m512i, __m512i, __mmask16)> {
    let t = taps16(g, row_coords16(coord, u, lanes), lanes)?;
    let (va, vb) = if g.cubic {
        sample_cubic16_pair((a, b), g, coord, u, &t)
    } else {
        let ((top_a, bot_a), (top_b, bot_b)) =
            match window(g, &t, falls(coord, u), a.len().min(b.len())) {
                Some(w) => (window_fetch(a, g, &w), window_fetch(b, g, &w)),
                None => (gather_pairs(a, g, &t), gather_pairs(b, g, &t)),
            };
        (interpolate(&t, top_a, bot_a), interpolate(&t, top_b, bot_b))
    };
    Some((va, vb, t.mask))
}

/// Finishes the first `n8` pixels (a multiple of 8) of a single-channel output
/// row from [`accumulate_row_gray`]'s sums: `out[u] = round(sum / (256 n))`
/// computed as the scalar `average` does (the same `f32` operations, and its
/// saturating conversion), `fill` where no frame covers the pixel (`n = 0`),
/// `coverage[u] = n`. Returns how many of them `full` frames cover.
///
/// # Safety
/// As [`accumulate_row_gray`]; `sum`, `count`, `out` and `coverage` must hold
/// at least `n8` values.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
pub(super) unsafe fn finish_row_gray(
    sum: &[u32],
    count: &[u32],
    out: &mut [u8],
    coverage: &mut [u8],
    n8: usize,
    full: u32,
    fill: u8,
) -> usize {
    debug_assert!(n8 & 7 == 0 && sum.len() >= n8 && count.len() >= n8);
    debug_assert!(out.len() >= n8 && coverage.len() >= n8);
    let (c256, half, one) = (
        _mm512_set1_ps(256.0),
        _mm512_set1_ps(0.5),
        _mm512_set1_ps(1.0),
    );
    let (max, fill, full) = (
        _mm512_set1_epi32(255),
        _mm512_set1_epi32(fill as i32),
        _mm512_set1_epi32(full as i32),
    );
    let mut complete = 0;
    let mut u = 0;
    while u < n8 {
        let lanes = step_lanes(n8, u);
        let s = _mm512_maskz_loadu_epi32(lanes, sum.as_ptr().add(u) as *const i32);
        let n = _mm512_maskz_loadu_epi32(lanes, count.as_ptr().add(u) as *const i32);
        // `sum as f32 * (1 / (256 n)) + 0.5`: exact conversions (sums stay
        // below 2^24), a correctly rounded division, no FMA. Where `n = 0`
        // the product is 0 * inf = NaN, which converts to i32::MIN and
        // clamps to 0, as `as u8` maps NaN.
        let r = _mm512_div_ps(one, _mm512_mul_ps(c256, _mm512_cvtepi32_ps(n)));
        let v = _mm512_add_ps(_mm512_mul_ps(_mm512_cvtepi32_ps(s), r), half);
        let v = _mm512_min_epi32(
            _mm512_max_epi32(_mm512_cvttps_epi32(v), _mm512_setzero_si512()),
            max,
        );
        let empty = _mm512_cmpeq_epi32_mask(n, _mm512_setzero_si512());
        let v = _mm512_mask_blend_epi32(empty, v, fill);
        _mm_mask_storeu_epi8(
            out.as_mut_ptr().add(u) as *mut i8,
            lanes,
            _mm512_cvtepi32_epi8(v),
        );
        _mm_mask_storeu_epi8(
            coverage.as_mut_ptr().add(u) as *mut i8,
            lanes,
            _mm512_cvtepi32_epi8(n),
        );
        complete += _mm512_mask_cmpeq_epi32_mask(lanes, n, full).count_ones() as usize;
        u += 16;
    }
    complete
}

/// The 8.8 fixed-point samples of output pixels `u..u + 16` of one plane (0 in
/// lanes outside it or outside `lanes`) and the lanes inside it; `None` when
/// no lane is inside.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
pub(super) unsafe fn sample_gray16(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    lanes: __mmask16,
) -> Option<(__m512i, __mmask16)> {
    let t = taps16(g, row_coords16(coord, u, lanes), lanes)?;
    if g.cubic {
        return Some((sample_cubic16(data, g, coord, u, &t), t.mask));
    }
    let (top, bot) =
        window_pairs(data, g, &t, falls(coord, u)).unwrap_or_else(|| gather_pairs(data, g, &t));
    Some((interpolate(&t, top, bot), t.mask))
}

/// The bicubic samples of output pixels `u..u + 16` of one plane, whose
/// bilinear footprints are `t` (0 outside `t.mask`): each lane's four tap rows
/// as four bytes in its 32-bit lane, from row windows by byte permutes
/// ([`CubicWindow`]) or else gathered ([`cubic_gather`]), then the AVX2
/// kernel's arithmetic (`sample_cubic_gray8`), sixteen lanes wide. A chunk
/// with a lane at the plane's edge (`x0` or `y0` on the first or last tap,
/// where this kernel's `x0` may also be one past the reference's with
/// `ax = 0`) is sampled lane by lane by the scalar reference. Not inlined, as
/// in the AVX2 kernel: the bilinear path it branches off from is, into every
/// row loop.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline(never)]
unsafe fn sample_cubic16(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    t: &Taps16,
) -> __m512i {
    if !cubic_interior16(g, t) {
        return cubic_reference16(data, g, coord, u, t);
    }
    let rows = match CubicWindow::of(g, t, falls(coord, u), data.len()) {
        Some(w) => w.fetch(data),
        None => cubic_gather(data, g, t),
    };
    cubic_sum16(rows, &CubicWeights16::of(t), t.mask)
}

/// [`sample_cubic16`] of two planes of one geometry (the U and V planes of
/// 4:2:0 frames): the weights and the window are found once for both. Not
/// inlined, as [`sample_cubic16`].
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline(never)]
unsafe fn sample_cubic16_pair(
    (a, b): (&[u8], &[u8]),
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    t: &Taps16,
) -> (__m512i, __m512i) {
    if !cubic_interior16(g, t) {
        return (
            cubic_reference16(a, g, coord, u, t),
            cubic_reference16(b, g, coord, u, t),
        );
    }
    let (rows_a, rows_b) = match CubicWindow::of(g, t, falls(coord, u), a.len().min(b.len())) {
        Some(w) => (w.fetch(a), w.fetch(b)),
        None => (cubic_gather(a, g, t), cubic_gather(b, g, t)),
    };
    let w = CubicWeights16::of(t);
    (
        cubic_sum16(rows_a, &w, t.mask),
        cubic_sum16(rows_b, &w, t.mask),
    )
}

/// Whether every lane of `t` inside the plane has all its bicubic taps inside
/// it (`1 <= x0 < max_x0`, `1 <= y0 < max_y0`); a chunk with a lane on the
/// plane's one-pixel edge band takes the reference ([`cubic_reference16`]).
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn cubic_interior16(g: &KernelGeometry, t: &Taps16) -> bool {
    let zero = _mm512_setzero_si512();
    let inside = |m: __mmask16, p0: __m512i, max0: i32| {
        let m = _mm512_mask_cmpgt_epi32_mask(m, p0, zero);
        _mm512_mask_cmplt_epi32_mask(m, p0, _mm512_set1_epi32(max0))
    };
    inside(inside(t.mask, t.x0, g.max_x0), t.y0, g.max_y0) == t.mask
}

/// The reference's samples of the lanes of `t` inside the plane, lane by lane
/// (the others are 0, and past a last step of eight there is no coordinate).
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn cubic_reference16(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    t: &Taps16,
) -> __m512i {
    let geom = g.scalar();
    let mut v = [0u32; 16];
    for (l, v) in v.iter_mut().enumerate() {
        if t.mask & (1 << l) != 0 {
            let (sx, sy) = coord.at(u + l);
            *v = geom.sample_gray(data, sx, sy).unwrap_or(0);
        }
    }
    _mm512_loadu_si512(v.as_ptr() as *const _)
}

/// The bicubic weights of a chunk: the horizontal ones as 16-bit pairs for
/// `madd` (`(w0, w1)`, `(w2, w3)`; zero outside the mask), the vertical ones
/// in 32-bit lanes.
struct CubicWeights16 {
    wx01: __m512i,
    wx23: __m512i,
    wy: [__m512i; 4],
}

impl CubicWeights16 {
    #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
    #[inline]
    unsafe fn of(t: &Taps16) -> Self {
        let (wx, wy) = (cubic_weights16(t.ax), cubic_weights16(t.ay));
        let low16 = _mm512_set1_epi32(0xFFFF);
        let pair = |lo: __m512i, hi: __m512i| {
            _mm512_maskz_or_epi32(
                t.mask,
                _mm512_and_si512(lo, low16),
                _mm512_slli_epi32::<16>(hi),
            )
        };
        Self {
            wx01: pair(wx[0], wx[1]),
            wx23: pair(wx[2], wx[3]),
            wy,
        }
    }
}

/// The bicubic samples from the four tap rows of a chunk (each lane's four
/// taps as the bytes of its 32-bit lane): the AVX2 kernel's arithmetic
/// (`sample_cubic_gray8`), sixteen lanes wide; 0 outside `mask`.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn cubic_sum16(rows: [__m512i; 4], w: &CubicWeights16, mask: __mmask16) -> __m512i {
    let (byte, hi_byte) = (_mm512_set1_epi32(0xFF), _mm512_set1_epi32(0xFF_0000));
    let mut acc = _mm512_set1_epi32(128);
    for (p, w_row) in rows.into_iter().zip(w.wy) {
        // Bytes 0, 1 and 2, 3 of each lane as 16-bit pairs.
        let p01 = _mm512_or_si512(
            _mm512_and_si512(p, byte),
            _mm512_and_si512(_mm512_slli_epi32::<8>(p), hi_byte),
        );
        let p23 = _mm512_or_si512(
            _mm512_and_si512(_mm512_srli_epi32::<16>(p), byte),
            _mm512_and_si512(_mm512_srli_epi32::<8>(p), hi_byte),
        );
        let along = _mm512_add_epi32(
            _mm512_madd_epi16(p01, w.wx01),
            _mm512_madd_epi16(p23, w.wx23),
        );
        acc = _mm512_add_epi32(acc, _mm512_mullo_epi32(along, w_row));
    }
    let v = _mm512_min_epi32(
        _mm512_max_epi32(_mm512_srai_epi32::<8>(acc), _mm512_setzero_si512()),
        _mm512_set1_epi32(255 * 256),
    );
    _mm512_maskz_mov_epi32(mask, v)
}

/// `common::cubic_weights` of sixteen 8-bit fractions, lane by lane.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn cubic_weights16(a: __m512i) -> [__m512i; 4] {
    let mul = |x: __m512i, k: i32| _mm512_mullo_epi32(x, _mm512_set1_epi32(k));
    let (a2, half) = (_mm512_mullo_epi32(a, a), _mm512_set1_epi32(1 << 16));
    let a3 = _mm512_mullo_epi32(a2, a);
    let sum = |terms: [__m512i; 3]| {
        let s = _mm512_add_epi32(_mm512_add_epi32(terms[0], terms[1]), terms[2]);
        _mm512_srai_epi32::<17>(_mm512_add_epi32(s, half))
    };
    let zero = _mm512_setzero_si512();
    let w0 = sum([_mm512_sub_epi32(zero, a3), mul(a2, 512), mul(a, -65536)]);
    let w2 = sum([mul(a3, -3), mul(a2, 1024), mul(a, 65536)]);
    let w3 = sum([a3, mul(a2, -256), zero]);
    let w1 = _mm512_sub_epi32(
        _mm512_set1_epi32(256),
        _mm512_add_epi32(_mm512_add_epi32(w0, w2), w3),
    );
    [w0, w1, w2, w3]
}

/// Where the four tap rows of interior taps `t` (each lane's bytes `x0 - 1
/// ..= x0 + 2` of rows `y0 - 1 ..= y0 + 2`) lie in 64-byte windows of five
/// rows of a plane `len` bytes long, or `None` when they do not fit: as
/// [`window`], with every lane's leftmost tap within 60 columns of the
/// window's start and its top row on one of two neighbouring rows. The same
/// for every plane of one geometry ([`CubicWindow::fetch`] reads one).
struct CubicWindow {
    /// Byte offset of the window's first row.
    start: usize,
    stride: usize,
    /// Bytes `off, off + 1, off + 2, off + 3` of a row window into each lane.
    index: __m512i,
    /// Lanes whose top tap row is the window's second row.
    lower: __mmask16,
}

impl CubicWindow {
    #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
    #[inline]
    unsafe fn of(g: &KernelGeometry, t: &Taps16, falls: bool, len: usize) -> Option<Self> {
        let one = _mm512_set1_epi32(1);
        let x_win = (_mm512_cvtsi512_si32(t.x0) - 1 - WINDOW_SLACK).max(0);
        let y_win = (_mm512_cvtsi512_si32(t.y0) - 1 - falls as i32).max(0);
        let off = _mm512_sub_epi32(_mm512_sub_epi32(t.x0, one), _mm512_set1_epi32(x_win));
        let down = _mm512_sub_epi32(_mm512_sub_epi32(t.y0, one), _mm512_set1_epi32(y_win));
        // Unsigned compares: a negative offset is out of the window too.
        if _mm512_mask_cmpgt_epu32_mask(t.mask, off, _mm512_set1_epi32(60)) != 0
            || _mm512_mask_cmpgt_epu32_mask(t.mask, down, one) != 0
        {
            return None;
        }
        let stride = g.stride as usize;
        let start = y_win as usize * stride + x_win as usize;
        if start + 4 * stride + 64 > len {
            return None;
        }
        Some(Self {
            start,
            stride,
            index: _mm512_add_epi32(
                _mm512_mullo_epi32(off, _mm512_set1_epi32(0x0101_0101)),
                _mm512_set1_epi32(0x0302_0100),
            ),
            lower: _mm512_mask_cmpneq_epi32_mask(t.mask, down, _mm512_setzero_si512()),
        })
    }

    /// The four tap rows of `data` (at least the `len` bytes the window was
    /// found for).
    #[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
    #[inline]
    unsafe fn fetch(&self, data: &[u8]) -> [__m512i; 4] {
        let row = |r: usize| {
            let bytes =
                _mm512_loadu_si512(data.as_ptr().add(self.start + r * self.stride) as *const _);
            _mm512_permutexvar_epi8(self.index, bytes)
        };
        let q = [row(0), row(1), row(2), row(3), row(4)];
        std::array::from_fn(|r| _mm512_mask_blend_epi32(self.lower, q[r], q[r + 1]))
    }
}

/// The four tap rows of interior taps `t`, gathered: one 32-bit load per lane
/// and row, from the leftmost tap on.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn cubic_gather(data: &[u8], g: &KernelGeometry, t: &Taps16) -> [__m512i; 4] {
    let (one, stride) = (_mm512_set1_epi32(1), _mm512_set1_epi32(g.stride));
    let at = _mm512_add_epi32(
        _mm512_mullo_epi32(_mm512_sub_epi32(t.y0, one), stride),
        _mm512_sub_epi32(t.x0, one),
    );
    let base = data.as_ptr() as *const i32;
    std::array::from_fn(|r| {
        let at = _mm512_add_epi32(at, _mm512_set1_epi32(r as i32 * g.stride));
        _mm512_mask_i32gather_epi32::<1>(_mm512_setzero_si512(), t.mask, at, base)
    })
}

/// The bilinear value from the taps' 16-bit pairs `(left, right)` of the top
/// and bottom rows: `(top by + bot ay + 128) >> 8` with `top = left bx + right
/// ax`, written as `256 top + (bot - top) ay`, the same integer with one
/// multiply instead of two; 0 in lanes outside the mask.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn interpolate(t: &Taps16, top: __m512i, bot: __m512i) -> __m512i {
    // Lanes outside the mask get zero weights, so their value is
    // `(0 + 128) >> 8 = 0` whatever their taps hold.
    let wx = _mm512_maskz_or_epi32(t.mask, t.bx, _mm512_slli_epi32::<16>(t.ax));
    let top = _mm512_madd_epi16(top, wx);
    let bot = _mm512_madd_epi16(bot, wx);
    let v = _mm512_add_epi32(
        _mm512_add_epi32(
            _mm512_slli_epi32::<8>(top),
            _mm512_mullo_epi32(_mm512_sub_epi32(bot, top), t.ay),
        ),
        _mm512_set1_epi32(128),
    );
    _mm512_srli_epi32::<8>(v)
}

/// The taps' pairs picked out of 64-byte windows of the rows they lie on, or
/// `None` when they do not fit (then [`gather_pairs`] fetches them): every
/// lane's left tap within [`WINDOW_SPAN`] columns of the window's start, and
/// every top tap on one of two neighbouring rows.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn window_pairs(
    data: &[u8],
    g: &KernelGeometry,
    t: &Taps16,
    falls: bool,
) -> Option<(__m512i, __m512i)> {
    let w = window(g, t, falls, data.len())?;
    Some(window_fetch(data, g, &w))
}

/// Where a chunk's taps lie in a plane: the window's first byte, each lane's
/// byte offsets in it, and the lanes whose top tap is on its second row.
struct Window {
    start: usize,
    index: __m512i,
    lower: __mmask16,
}

/// The [`Window`] of taps `t` in planes of `len` bytes (see [`window_pairs`]);
/// it depends on the geometry alone, so planes of one geometry share it.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn window(g: &KernelGeometry, t: &Taps16, falls: bool, len: usize) -> Option<Window> {
    // The window starts at lane 0's taps, [`WINDOW_SLACK`] columns to the
    // left, on its top row or the row above where `y` falls along the row.
    // Lane 0 alone: taking the run's far end too (two more extractions and
    // their scalar work per frame and step) cost ~12% of the render.
    let x_win = (_mm512_cvtsi512_si32(t.x0) - WINDOW_SLACK).max(0);
    let y_win = (_mm512_cvtsi512_si32(t.y0) - falls as i32).max(0);
    let off = _mm512_sub_epi32(t.x0, _mm512_set1_epi32(x_win));
    let down = _mm512_sub_epi32(t.y0, _mm512_set1_epi32(y_win));
    // Unsigned compares: a negative offset is out of the window too.
    if _mm512_mask_cmpgt_epu32_mask(t.mask, off, _mm512_set1_epi32(WINDOW_SPAN)) != 0
        || _mm512_mask_cmpgt_epu32_mask(t.mask, down, _mm512_set1_epi32(1)) != 0
    {
        return None;
    }
    // All three rows are read, whether or not a lane needs the third: a
    // branch on it was mispredicted on about a third of the chunks under a
    // slight roll, and cost more than the load.
    let start = y_win as usize * g.stride as usize + x_win as usize;
    if start + 2 * g.stride as usize + 64 > len {
        return None;
    }
    Some(Window {
        start,
        // Lanes whose top tap is on the window's second row.
        lower: _mm512_mask_cmpneq_epi32_mask(t.mask, down, _mm512_setzero_si512()),
        // Byte 0 of each lane: the left tap's offset; byte 2: the right one's.
        index: _mm512_or_si512(
            off,
            _mm512_slli_epi32::<16>(_mm512_add_epi32(off, _mm512_set1_epi32(1))),
        ),
    })
}

/// The taps' pairs of the top and bottom rows, out of window `w` of `data`.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn window_fetch(data: &[u8], g: &KernelGeometry, w: &Window) -> (__m512i, __m512i) {
    let stride = g.stride as usize;
    // The row below the window, a line ahead: what the next output row's
    // window at this place will read. Without it, those lines come from
    // beyond L2 when they are first read (the frames of one output are ~6x
    // the size of L2) and the kernel waits on them.
    let ahead = data.as_ptr().wrapping_add(w.start + 3 * stride + 64);
    _mm_prefetch::<_MM_HINT_T0>(ahead as *const i8);
    let row = |r: usize| {
        let bytes = _mm512_loadu_si512(data.as_ptr().add(w.start + r * stride) as *const _);
        _mm512_maskz_permutexvar_epi8(PAIR_BYTES, w.index, bytes)
    };
    let (first, second, third) = (row(0), row(1), row(2));
    (
        _mm512_mask_blend_epi32(w.lower, first, second),
        _mm512_mask_blend_epi32(w.lower, second, third),
    )
}

/// The taps' pairs `(left, right)` of the top and bottom rows as 16-bit words,
/// gathered: one 32-bit load per lane and row, from the tap's byte on.
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn gather_pairs(data: &[u8], g: &KernelGeometry, t: &Taps16) -> (__m512i, __m512i) {
    let stride = _mm512_set1_epi32(g.stride);
    let i0 = _mm512_add_epi32(_mm512_mullo_epi32(t.y0, stride), t.x0);
    let i1 = _mm512_add_epi32(i0, stride);
    let z = _mm512_setzero_si512();
    let base = data.as_ptr() as *const i32;
    let p0 = _mm512_mask_i32gather_epi32::<1>(z, t.mask, i0, base);
    let p1 = _mm512_mask_i32gather_epi32::<1>(z, t.mask, i1, base);
    let (byte, hi_byte) = (_mm512_set1_epi32(0xFF), _mm512_set1_epi32(0xFF_0000));
    let pair = |p: __m512i| {
        _mm512_or_si512(
            _mm512_and_si512(p, byte),
            _mm512_and_si512(_mm512_slli_epi32::<8>(p), hi_byte),
        )
    };
    (pair(p0), pair(p1))
}

/// Source coordinates of output pixels `u..u + 16` of one frame's row (lanes
/// outside `lanes` are not read): loaded from its table, or evaluated from its
/// homography exactly as the scalar formula does (no FMA, same order).
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn row_coords16(coord: &RowCoords<'_>, u: usize, lanes: __mmask16) -> (__m512, __m512) {
    match *coord {
        RowCoords::Table(xs, ys) => (
            _mm512_maskz_loadu_ps(lanes, xs.as_ptr().add(u)),
            _mm512_maskz_loadu_ps(lanes, ys.as_ptr().add(u)),
        ),
        RowCoords::Homography(h) => {
            let lane = _mm512_setr_ps(
                0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0,
                15.0,
            );
            let uf = _mm512_add_ps(_mm512_set1_ps(u as f32), lane);
            let z = _mm512_add_ps(
                _mm512_set1_ps(h.z0),
                _mm512_mul_ps(_mm512_set1_ps(h.dz), uf),
            );
            let ahead = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(z, _mm512_set1_ps(1e-6));
            let iz = _mm512_mask_blend_ps(
                ahead,
                _mm512_set1_ps(f32::NAN),
                _mm512_div_ps(_mm512_set1_ps(1.0), z),
            );
            let x = _mm512_add_ps(
                _mm512_set1_ps(h.x0),
                _mm512_mul_ps(_mm512_set1_ps(h.dx), uf),
            );
            let y = _mm512_add_ps(
                _mm512_set1_ps(h.y0),
                _mm512_mul_ps(_mm512_set1_ps(h.dy), uf),
            );
            (_mm512_mul_ps(x, iz), _mm512_mul_ps(y, iz))
        }
    }
}

/// The bilinear footprint of sixteen sample points, as `Taps8` in the AVX2
/// kernel: the lanes inside the plane, the top-left tap `(x0, y0)` of each
/// (0 outside), and the 8-bit weights `ax = round(256 fx)`, `bx = 256 - ax`, `ay`.
struct Taps16 {
    mask: __mmask16,
    x0: __m512i,
    y0: __m512i,
    ax: __m512i,
    ay: __m512i,
    bx: __m512i,
}

/// [`Taps16`] of the points `(sx, sy)` of the lanes in `lanes`; `None` when
/// no lane is inside (NaN compares false: NaN points are outside).
#[target_feature(enable = "avx512f,avx512bw,avx512vl,avx512vbmi")]
#[inline]
unsafe fn taps16(
    g: &KernelGeometry,
    (sx, sy): (__m512, __m512),
    lanes: __mmask16,
) -> Option<Taps16> {
    let lo = _mm512_set1_ps(-EDGE_TOLERANCE);
    let mut mask = _mm512_mask_cmp_ps_mask::<_CMP_GE_OQ>(lanes, sx, lo);
    mask = _mm512_mask_cmp_ps_mask::<_CMP_GE_OQ>(mask, sy, lo);
    mask =
        _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(mask, sx, _mm512_set1_ps(g.max_x + EDGE_TOLERANCE));
    mask =
        _mm512_mask_cmp_ps_mask::<_CMP_LE_OQ>(mask, sy, _mm512_set1_ps(g.max_y + EDGE_TOLERANCE));
    if mask == 0 {
        return None;
    }
    // In 8.8 fixed point, `p = trunc(256 s + 0.5)` with `s` clamped onto the
    // plane: `256 s` is exact (a power of two), so `p = 256 x0 + ax` with
    // `x0 = floor(s)` and `ax = round(256 (s - x0))` exactly as the
    // reference computes them. A point within the tolerance left of the
    // plane gives `p = 0` (it truncates towards 0); one past its right end is
    // clamped to `256 max`. Lanes outside are zeroed (coordinate 0).
    let (c256, half) = (_mm512_set1_ps(256.0), _mm512_set1_ps(0.5));
    let fixed = |s: __m512, max: f32| {
        let p = _mm512_cvttps_epi32(_mm512_maskz_fmadd_ps(mask, s, c256, half));
        _mm512_min_epi32(p, _mm512_set1_epi32((max * 256.0) as i32))
    };
    let (px, py) = (fixed(sx, g.max_x), fixed(sy, g.max_y));
    // Where the reference takes `x0 = max_x0, ax = 256` at the right edge,
    // this takes `x0 = max_x0 + 1, ax = 0`: the same value, its right tap
    // weighted 0 (the byte after the row: the next row's first, or the
    // frame padding). Rows are clamped as the reference does: a row below
    // the last must not be read.
    let x0 = _mm512_srai_epi32::<8>(px);
    let ax = _mm512_and_si512(px, _mm512_set1_epi32(255));
    let y0 = _mm512_min_epi32(_mm512_srai_epi32::<8>(py), _mm512_set1_epi32(g.max_y0));
    let ay = _mm512_sub_epi32(py, _mm512_slli_epi32::<8>(y0));
    Some(Taps16 {
        mask,
        x0,
        y0,
        ax,
        ay,
        bx: _mm512_sub_epi32(_mm512_set1_epi32(256), ax),
    })
}

#[cfg(test)]
mod tests {
    use super::super::common::{affine_row, Geometry};
    use super::*;

    /// The window path and the gathers fetch the same pairs wherever the window
    /// applies, it applies to the rows a rotation makes (so the fast path is
    /// what runs), and it declines runs that do not fit.
    #[test]
    fn window_pairs_match_gathers() {
        if !available() {
            eprintln!("skipped: no AVX-512 VBMI on this CPU");
            return;
        }
        let (w, h) = (203usize, 97usize);
        let plane: Vec<u8> = (0..w * h + 4)
            .map(|i| (i.wrapping_mul(2654435761) >> 7) as u8)
            .collect();
        let g = KernelGeometry::of(&Geometry::plane(w, h, 1));
        let pairs = |coord: RowCoords<'_>, u: usize| -> (Option<[[i32; 16]; 2]>, [[i32; 16]; 2]) {
            // SAFETY: this CPU has the features (checked above); the plane is padded.
            unsafe {
                let t = taps16(&g, row_coords16(&coord, u, 0xFFFF), 0xFFFF).unwrap();
                let words = |(a, b): (__m512i, __m512i)| {
                    let (mut x, mut y) = ([0i32; 16], [0i32; 16]);
                    _mm512_storeu_si512(
                        x.as_mut_ptr() as *mut _,
                        _mm512_maskz_mov_epi32(t.mask, a),
                    );
                    _mm512_storeu_si512(
                        y.as_mut_ptr() as *mut _,
                        _mm512_maskz_mov_epi32(t.mask, b),
                    );
                    [x, y]
                };
                (
                    window_pairs(&plane, &g, &t, falls(&coord, u)).map(words),
                    words(gather_pairs(&plane, &g, &t)),
                )
            }
        };
        // A slight roll and zoom: the taps straddle two rows, then one.
        for (coord, u) in [
            (affine_row(10.3, 40.6, 1.13, 0.07), 16),
            (affine_row(3.7, 20.2, 0.93, -0.04), 32),
            (affine_row(-0.4, 0.0, 1.0, 0.0), 0),
        ] {
            let (window, gathered) = pairs(coord, u);
            assert_eq!(window, Some(gathered), "{coord:?} at {u}");
        }
        // Too steep (taps on four rows), too wide (a 5x zoom-out), too close to
        // the plane's end for a 64-byte window: the gathers take over.
        for (coord, u) in [
            (affine_row(10.3, 40.6, 0.9, 0.5), 16),
            (affine_row(1.0, 10.0, 5.0, 0.0), 0),
            (affine_row(180.0, (h - 2) as f32, 1.0, 0.0), 0),
        ] {
            assert_eq!(pairs(coord, u).0, None, "{coord:?} at {u}");
        }
    }
}
