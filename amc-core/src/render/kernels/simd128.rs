//! The WebAssembly `simd128` row kernels and row finishers (used when the
//! module is built with `+simd128`). Planes sampled bicubically take four
//! 32-bit lane loads a pixel, one per tap row (`sample_cubic_gray4`), and
//! interleaved frames sixteen, one per tap (`sample_cubic_rgb4`).

use super::common::{KernelGeometry, RowCoords, EDGE_TOLERANCE};
use crate::render::robust::{Deghost, FULL_WEIGHT};
use core::arch::wasm32::*;

/// The WebAssembly `simd128` twin of the AVX2 kernel (`avx2.rs`): four output
/// pixels at a time, one frame after the other. WebAssembly has no gathers, so each lane's taps are read
/// one lane at a time, straight into the lane (an RGBA pixel and its right
/// neighbour in one 8-byte `load64_lane`; lanes outside the frame read offset
/// 0 and are masked off). Float-to-int
/// conversions of the (non-negative, integral) coordinates use the `2^23`
/// trick instead of the slow saturating conversion; the interpolation is the
/// same 8.8 fixed-point integer arithmetic (`i32x4.dot_i16x8_s` plays
/// `vpmaddwd`), bit-exact with the scalar reference in `scalar.rs`.
///
/// # Safety
/// Every `datas[f]` must be non-empty and hold the whole frame plus
/// [`super::FRAME_PADDING`] bytes; coordinate tables and the outputs must have at
/// least `n8` elements (`n8` a multiple of 4).
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn accumulate_row(
    datas: &[&[u8]],
    g: KernelGeometry,
    coords: &[RowCoords<'_>],
    n8: usize,
    acc_r: &mut [u32],
    acc_g: &mut [u32],
    acc_b: &mut [u32],
    count: &mut [u32],
) {
    debug_assert!(n8 % 4 == 0 && datas.len() == coords.len());
    debug_assert!(acc_r.len() >= n8 && acc_g.len() >= n8 && acc_b.len() >= n8 && count.len() >= n8);
    let one = i32x4_splat(1);
    // Frame-outer (unlike the AVX2 kernel): each frame's row is read as one
    // stream and the row sums (a few KiB) stay in L1; at 720p this is ~30%
    // faster in V8 than keeping sums in registers across frames.
    for acc in [&mut *acc_r, &mut *acc_g, &mut *acc_b, &mut *count] {
        acc[..n8].fill(0);
    }
    for (data, coord) in datas.iter().zip(coords) {
        let mut u = 0;
        while u < n8 {
            if let Some(([r, gg, b], valid)) = sample_rgb4(data, &g, coord, u) {
                for (acc, v) in [
                    (acc_r.as_mut_ptr(), r),
                    (acc_g.as_mut_ptr(), gg),
                    (acc_b.as_mut_ptr(), b),
                    (count.as_mut_ptr(), v128_and(valid, one)),
                ] {
                    let p = acc.add(u) as *mut v128;
                    v128_store(p, i32x4_add(v128_load(p), v));
                }
            }
            u += 4;
        }
    }
}

/// The 8.8 fixed-point R, G, B samples of four output pixels `u..u + 4` of one
/// frame (0 in lanes outside it) and the lanes inside it (all bits set); `None`
/// when no lane is inside.
#[inline(always)]
unsafe fn sample_rgb4(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
) -> Option<([v128; 3], v128)> {
    let stride = i32x4_splat(g.stride);
    let chans = i32x4_splat(g.channels);
    let i128 = i32x4_splat(128);
    let byte = i32x4_splat(0xFF);
    let hi_byte = i32x4_splat(0xFF_0000);
    let lo_bytes = i16x8_splat(0x00FF);
    let (s, c) = (g.stride as usize, g.channels as usize);
    let rgba = c == 4;
    let stride_f = f32x4_splat(g.stride as f32);
    let chans_f = f32x4_splat(g.channels as f32);
    // Largest offset computed: (max_y0 * stride + max_x0 * channels).
    let small_frame =
        (g.max_y0 as i64 * g.stride as i64 + g.max_x0 as i64 * g.channels as i64) < (1 << 23);
    let base = data.as_ptr();
    let t = taps4(g, row_coords4(coord, u))?;
    if g.cubic {
        return Some(sample_cubic_rgb4(data, g, coord, u, &t));
    }
    let Taps4 {
        valid,
        x0f,
        y0f,
        ax,
        ay,
        bx,
        by,
    } = t;
    // Byte offsets: in f32 when every offset is below 2^23 (exact,
    // and no 32-bit multiplies), else in integers.
    let i00 = if small_frame {
        to_int(f32x4_add(f32x4_mul(y0f, stride_f), f32x4_mul(x0f, chans_f)))
    } else {
        i32x4_add(
            i32x4_mul(to_int(y0f), stride),
            i32x4_mul(to_int(x0f), chans),
        )
    };
    // Lanes hold 16-bit pairs (left, right) and (bx, ax): the signed
    // 16-bit dot product gives left*bx + right*ax. Invalid lanes get
    // zero weights, so they come out as (0 + 0 + 128) >> 8 = 0.
    let wx = v128_and(v128_or(bx, i32x4_shl(ax, 16)), valid);
    let vertical = |top: v128, bot: v128| {
        let top = i32x4_dot_i16x8(top, wx);
        let bot = i32x4_dot_i16x8(bot, wx);
        let v = i32x4_add(i32x4_add(i32x4_mul(top, by), i32x4_mul(bot, ay)), i128);
        u32x4_shr(v, 8)
    };
    let (r, gg, b);
    if rgba {
        // A pixel and its right neighbour are one 8-byte load:
        // bytes r0 g0 b0 a0 r1 g1 b1 a1, straight into a 64-bit lane
        // (`v128.load64_zero` / `load64_lane`: no general registers).
        let at = |i: usize| base.add(i) as *const u64;
        let pair = |i: usize, j: usize| v128_load64_lane::<1>(v128_load64_zero(at(i)), at(j));
        let i0 = i32x4_extract_lane::<0>(i00) as usize;
        let i1 = i32x4_extract_lane::<1>(i00) as usize;
        let i2 = i32x4_extract_lane::<2>(i00) as usize;
        let i3 = i32x4_extract_lane::<3>(i00) as usize;
        let top01 = pair(i0, i1);
        let top23 = pair(i2, i3);
        let bot01 = pair(i0 + s, i1 + s);
        let bot23 = pair(i2 + s, i3 + s);
        // Per 64-bit half (one lane's two pixels), 16-bit words
        // (r0 g0) (b0 a0) (r1 g1) (b1 a1): masking the low or high
        // bytes and swapping the middle words gives the 32-bit pairs
        // (r0, r1) (b0, b1) or (g0, g1) (a0, a1); then lanes are
        // gathered per channel. Only single-input word shuffles and
        // `shufps`-like dword shuffles: cheap in wasm engines.
        let swap = |v: v128| i16x8_shuffle::<0, 2, 1, 3, 4, 6, 5, 7>(v, v);
        let split = |p01: v128, p23: v128| {
            let rb01 = swap(v128_and(p01, lo_bytes));
            let rb23 = swap(v128_and(p23, lo_bytes));
            let ga01 = swap(u16x8_shr(p01, 8));
            let ga23 = swap(u16x8_shr(p23, 8));
            (
                i32x4_shuffle::<0, 2, 4, 6>(rb01, rb23),
                i32x4_shuffle::<0, 2, 4, 6>(ga01, ga23),
                i32x4_shuffle::<1, 3, 5, 7>(rb01, rb23),
            )
        };
        let (tr, tg, tb) = split(top01, top23);
        let (br, bg, bb) = split(bot01, bot23);
        r = vertical(tr, br);
        gg = vertical(tg, bg);
        b = vertical(tb, bb);
    } else {
        // Each tap's 4 bytes (its RGB and one more) straight into its lane.
        let (mut p00, mut p01, mut p10, mut p11) = (
            i32x4_splat(0),
            i32x4_splat(0),
            i32x4_splat(0),
            i32x4_splat(0),
        );
        macro_rules! taps {
            ($l:literal) => {{
                let p = base.add(i32x4_extract_lane::<$l>(i00) as usize);
                p00 = v128_load32_lane::<$l>(p00, p as *const u32);
                p01 = v128_load32_lane::<$l>(p01, p.add(c) as *const u32);
                p10 = v128_load32_lane::<$l>(p10, p.add(s) as *const u32);
                p11 = v128_load32_lane::<$l>(p11, p.add(s + c) as *const u32);
            }};
        }
        taps!(0);
        taps!(1);
        taps!(2);
        taps!(3);
        macro_rules! channel {
            ($shift:expr, $up:expr) => {{
                let top = v128_or(
                    v128_and(u32x4_shr(p00, $shift), byte),
                    v128_and(i32x4_shl(p01, $up), hi_byte),
                );
                let bot = v128_or(
                    v128_and(u32x4_shr(p10, $shift), byte),
                    v128_and(i32x4_shl(p11, $up), hi_byte),
                );
                vertical(top, bot)
            }};
        }
        r = channel!(0, 16);
        gg = channel!(8, 8);
        b = channel!(16, 0);
    }
    Some(([r, gg, b], valid))
}

/// The ghost-free weights of four samples differing by `d` from the
/// reference's: `Deghost::weight` lane by lane (`d <= 65280`), 16 where the
/// reference does not cover the pixel (`reference` lanes clear), 0 where the
/// frame does not (`valid` clear).
#[inline(always)]
fn weights4(deghost: Deghost, d: v128, reference: v128, valid: v128) -> v128 {
    let (zero_at, slope) = deghost.constants();
    let full = i32x4_splat(FULL_WEIGHT as i32);
    let ramp = i32x4_max(i32x4_sub(i32x4_splat(zero_at), d), i32x4_splat(0));
    let w = i32x4_min(u32x4_shr(i32x4_mul(ramp, i32x4_splat(slope)), 16), full);
    v128_and(v128_bitselect(w, full, reference), valid)
}

/// The ghost-free twin of [`accumulate_row`] (reference: `scalar::merge_row`):
/// four pixels at a time, frame-inner (the last frame's samples stay in
/// registers while the others are weighted against them).
///
/// # Safety
/// As [`accumulate_row`], and `datas` must not be empty.
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
    debug_assert!(n8 % 4 == 0 && datas.len() == coords.len() && !datas.is_empty());
    let [sum_r, sum_g, sum_b] = sum;
    debug_assert!(sum_r.len() >= n8 && sum_g.len() >= n8 && sum_b.len() >= n8);
    debug_assert!(weight.len() >= n8 && count.len() >= n8);
    let last = datas.len() - 1;
    let one = i32x4_splat(1);
    let full = i32x4_splat(FULL_WEIGHT as i32);
    let z = i32x4_splat(0);
    let absdiff = |a: v128, b: v128| i32x4_abs(i32x4_sub(a, b));
    let mut u = 0;
    while u < n8 {
        let ([r0, g0, b0], m0) =
            sample_rgb4(datas[last], &g, &coords[last], u).unwrap_or(([z; 3], z));
        let w0 = v128_and(m0, full);
        let (mut acc_r, mut acc_g, mut acc_b) =
            (i32x4_mul(w0, r0), i32x4_mul(w0, g0), i32x4_mul(w0, b0));
        let (mut acc_w, mut acc_n) = (w0, v128_and(m0, one));
        for (data, coord) in datas[..last].iter().zip(coords) {
            let Some(([r, gg, b], valid)) = sample_rgb4(data, &g, coord, u) else {
                continue;
            };
            let d = i32x4_max(i32x4_max(absdiff(r, r0), absdiff(gg, g0)), absdiff(b, b0));
            let w = weights4(deghost, d, m0, valid);
            acc_r = i32x4_add(acc_r, i32x4_mul(w, r));
            acc_g = i32x4_add(acc_g, i32x4_mul(w, gg));
            acc_b = i32x4_add(acc_b, i32x4_mul(w, b));
            acc_w = i32x4_add(acc_w, w);
            acc_n = i32x4_add(acc_n, v128_and(valid, one));
        }
        v128_store(sum_r.as_mut_ptr().add(u) as *mut v128, acc_r);
        v128_store(sum_g.as_mut_ptr().add(u) as *mut v128, acc_g);
        v128_store(sum_b.as_mut_ptr().add(u) as *mut v128, acc_b);
        v128_store(weight.as_mut_ptr().add(u) as *mut v128, acc_w);
        v128_store(count.as_mut_ptr().add(u) as *mut v128, acc_n);
        u += 4;
    }
}

/// The single-channel twin of [`merge_row`] (reference: `scalar::merge_row_gray`).
///
/// # Safety
/// As [`accumulate_row_gray`], and `datas` must not be empty.
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
    debug_assert!(n8 % 4 == 0 && datas.len() == coords.len() && !datas.is_empty());
    debug_assert!(sum.len() >= n8 && weight.len() >= n8 && count.len() >= n8);
    let last = datas.len() - 1;
    let one = i32x4_splat(1);
    let full = i32x4_splat(FULL_WEIGHT as i32);
    let z = i32x4_splat(0);
    let mut u = 0;
    while u < n8 {
        let (v0, m0) = sample_gray4(datas[last], &g, &coords[last], u).unwrap_or((z, z));
        let w0 = v128_and(m0, full);
        let mut acc = i32x4_mul(w0, v0);
        let (mut acc_w, mut acc_n) = (w0, v128_and(m0, one));
        for (data, coord) in datas[..last].iter().zip(coords) {
            let Some((v, valid)) = sample_gray4(data, &g, coord, u) else {
                continue;
            };
            let w = weights4(deghost, i32x4_abs(i32x4_sub(v, v0)), m0, valid);
            acc = i32x4_add(acc, i32x4_mul(w, v));
            acc_w = i32x4_add(acc_w, w);
            acc_n = i32x4_add(acc_n, v128_and(valid, one));
        }
        v128_store(sum.as_mut_ptr().add(u) as *mut v128, acc);
        v128_store(weight.as_mut_ptr().add(u) as *mut v128, acc_w);
        v128_store(count.as_mut_ptr().add(u) as *mut v128, acc_n);
        u += 4;
    }
}

/// Finishes `n8` pixels (a multiple of 4) of an RGBA output row from the
/// kernel's sums: `round(sum / (256 n))` per channel, alpha 255, exactly the
/// scalar `(sum as f32 * (1 / (256 n)) + 0.5) as u8` (0 where `n = 0`).
///
/// # Safety
/// The sums must hold at least `n8` values and `out` at least `4 * n8` bytes.
pub(super) unsafe fn finish_row_rgba(
    acc_r: &[u32],
    acc_g: &[u32],
    acc_b: &[u32],
    count: &[u32],
    out: &mut [u8],
    n8: usize,
) {
    debug_assert!(n8 % 4 == 0 && out.len() >= 4 * n8);
    let one = f32x4_splat(1.0);
    let c256 = f32x4_splat(256.0);
    let half = f32x4_splat(0.5);
    let magic = f32x4_splat(8_388_608.0);
    let magic_bits = i32x4_splat(0x4B00_0000);
    let max = i32x4_splat(255);
    let alpha = i32x4_splat(0xFF00_0000_u32 as i32);
    let zero = i32x4_splat(0);
    let mut u = 0;
    while u < n8 {
        let n = v128_load(count.as_ptr().add(u) as *const v128);
        let k = f32x4_div(one, f32x4_mul(c256, f32x4_convert_i32x4(n)));
        let covered = i32x4_ne(n, zero);
        // Sums are below 2^24 (64 frames of 255 * 256): exact as f32; the
        // rounded values are integral and in 0..=255 (NaN where n = 0, masked).
        let ch = |p: *const u32| {
            let x = f32x4_convert_i32x4(v128_load(p.add(u) as *const v128));
            let t = f32x4_trunc(f32x4_add(f32x4_mul(x, k), half));
            let v = i32x4_sub(f32x4_add(t, magic), magic_bits);
            v128_and(i32x4_min(v, max), covered)
        };
        let r = ch(acc_r.as_ptr());
        let g = ch(acc_g.as_ptr());
        let b = ch(acc_b.as_ptr());
        let px = v128_or(
            v128_or(r, i32x4_shl(g, 8)),
            v128_or(i32x4_shl(b, 16), alpha),
        );
        v128_store(out.as_mut_ptr().add(4 * u) as *mut v128, px);
        u += 4;
    }
}

/// Finishes `n8` pixels (a multiple of 4) of a single-channel output row
/// (a plane of a planar frame) from the kernel's sums, as the scalar pass in
/// the warper does: `(sum as f32 * (1 / (256 n)) + 0.5) as u8`, `fill` where
/// `n = 0`, the coverage `n` as a byte; returns the pixels whose count is
/// `full`. (The scalar pass did not vectorize in V8: it was 9% of a 320x180
/// render.)
///
/// # Safety
/// `sum` and `count` must hold at least `n8` values, `out` and `coverage` at
/// least `n8` bytes.
pub(super) unsafe fn finish_row_gray(
    sum: &[u32],
    count: &[u32],
    out: &mut [u8],
    coverage: &mut [u8],
    n8: usize,
    full: u32,
    fill: u8,
) -> usize {
    debug_assert!(n8 % 4 == 0 && sum.len() >= n8 && count.len() >= n8);
    debug_assert!(out.len() >= n8 && coverage.len() >= n8);
    let one = f32x4_splat(1.0);
    let c256 = f32x4_splat(256.0);
    let half = f32x4_splat(0.5);
    let magic = f32x4_splat(8_388_608.0);
    let magic_bits = i32x4_splat(0x4B00_0000);
    let max = i32x4_splat(255);
    let zero = i32x4_splat(0);
    let (fill, full) = (i32x4_splat(fill as i32), i32x4_splat(full as i32));
    // Byte 0 of each 32-bit lane, packed into the low 4 bytes.
    let bytes = |v: v128| {
        i8x16_swizzle(
            v,
            i8x16(0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1),
        )
    };
    let mut complete = 0;
    let mut u = 0;
    while u < n8 {
        let n = v128_load(count.as_ptr().add(u) as *const v128);
        let k = f32x4_div(one, f32x4_mul(c256, f32x4_convert_i32x4(n)));
        // Sums are below 2^24 (64 frames of 255 * 256): exact as f32; the
        // rounded values are integral and in 0..=255 (NaN where n = 0,
        // replaced by `fill`).
        let x = f32x4_convert_i32x4(v128_load(sum.as_ptr().add(u) as *const v128));
        let t = f32x4_trunc(f32x4_add(f32x4_mul(x, k), half));
        let v = i32x4_min(i32x4_sub(f32x4_add(t, magic), magic_bits), max);
        let v = v128_bitselect(fill, v, i32x4_eq(n, zero));
        v128_store32_lane::<0>(bytes(v), out.as_mut_ptr().add(u) as *mut u32);
        v128_store32_lane::<0>(bytes(n), coverage.as_mut_ptr().add(u) as *mut u32);
        complete += i32x4_bitmask(i32x4_eq(n, full)).count_ones() as usize;
        u += 4;
    }
    complete
}

/// The single-channel twin of [`accumulate_row`] for the planes of planar
/// frames: four output pixels at a time, frame-outer; each lane's taps are two
/// 16-bit loads (a tap and its right neighbour, in the row and the row below).
/// Bit-exact with the scalar `accumulate_row_gray`.
///
/// # Safety
/// Every `datas[f]` must hold the whole plane plus 2 readable bytes
/// ([`super::FRAME_PADDING`] covers it); coordinate tables and the outputs must
/// have at least `n8` elements (`n8` a multiple of 4).
pub(super) unsafe fn accumulate_row_gray(
    datas: &[&[u8]],
    g: KernelGeometry,
    coords: &[RowCoords<'_>],
    n8: usize,
    acc: &mut [u32],
    count: &mut [u32],
) {
    debug_assert!(n8 % 4 == 0 && datas.len() == coords.len());
    debug_assert!(acc.len() >= n8 && count.len() >= n8);
    let one = i32x4_splat(1);
    acc[..n8].fill(0);
    count[..n8].fill(0);
    for (data, coord) in datas.iter().zip(coords) {
        let mut u = 0;
        while u < n8 {
            if let Some((v, valid)) = sample_gray4(data, &g, coord, u) {
                for (dst, v) in [
                    (acc.as_mut_ptr(), v),
                    (count.as_mut_ptr(), v128_and(valid, one)),
                ] {
                    let p = dst.add(u) as *mut v128;
                    v128_store(p, i32x4_add(v128_load(p), v));
                }
            }
            u += 4;
        }
    }
}

/// [`accumulate_row_gray`] of two planes of one geometry at once (the U and
/// V planes of 4:2:0 frames): `acc_a` and `acc_b` from `datas_a` and
/// `datas_b`, one `count`; each chunk's coordinates and taps are found once
/// for both planes.
///
/// # Safety
/// As [`accumulate_row_gray`], for both planes' data.
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
    debug_assert!(n8 % 4 == 0 && datas_a.len() == coords.len() && datas_b.len() == coords.len());
    debug_assert!(acc_a.len() >= n8 && acc_b.len() >= n8 && count.len() >= n8);
    let one = i32x4_splat(1);
    acc_a[..n8].fill(0);
    acc_b[..n8].fill(0);
    count[..n8].fill(0);
    for ((a, b), coord) in datas_a.iter().zip(datas_b).zip(coords) {
        let mut u = 0;
        while u < n8 {
            if let Some(t) = taps4(&g, row_coords4(coord, u)) {
                let t = PlaneTaps4::of(&g, t);
                for (dst, v) in [
                    (acc_a.as_mut_ptr(), t.sample(a)),
                    (acc_b.as_mut_ptr(), t.sample(b)),
                    (count.as_mut_ptr(), v128_and(t.valid, one)),
                ] {
                    let p = dst.add(u) as *mut v128;
                    v128_store(p, i32x4_add(v128_load(p), v));
                }
            }
            u += 4;
        }
    }
}

/// The 8.8 fixed-point samples of four output pixels `u..u + 4` of one plane
/// (0 in lanes outside it) and the lanes inside it; `None` when no lane is inside.
#[inline(always)]
unsafe fn sample_gray4(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
) -> Option<(v128, v128)> {
    let t = taps4(g, row_coords4(coord, u))?;
    if g.cubic {
        return Some(sample_cubic_gray4(data, g, coord, u, &t));
    }
    let t = PlaneTaps4::of(g, t);
    Some((t.sample(data), t.valid))
}

/// The bicubic samples of four output pixels `u..u + 4` of one plane, whose
/// bilinear footprints are `t` (see `common::cubic_weights`), as the AVX2
/// kernel's `sample_cubic_gray8`: each lane's four tap rows are four 32-bit
/// lane loads, their bytes spread to 16-bit pairs for `i32x4.dot_i16x8_s`,
/// the rows weighted in 32-bit lanes; a chunk with a lane at the plane's edge
/// goes to the scalar reference. Lanes outside the plane read its first bytes
/// (offset 0 plus nothing: no tap row below it is read) with zero weights.
#[inline(always)]
unsafe fn sample_cubic_gray4(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    t: &Taps4,
) -> (v128, v128) {
    let (x0, y0) = (to_int(t.x0f), to_int(t.y0f));
    let (zero, one) = (i32x4_splat(0), i32x4_splat(1));
    if !cubic_interior4(g, t.valid, x0, y0) {
        let geom = g.scalar();
        let ([v], m) = cubic_reference4(coord, u, |sx, sy| {
            geom.sample_gray(data, sx, sy).map(|v| [v])
        });
        return (v, m);
    }
    let CubicWeights4 { wx01, wx23, wy } = CubicWeights4::of(t);
    // Tap (x0 - 1, y0 - 1) of every lane inside the plane.
    let at = i32x4_add(
        i32x4_mul(i32x4_sub(y0, one), i32x4_splat(g.stride)),
        i32x4_sub(x0, one),
    );
    let base = data.as_ptr();
    let (byte, hi_byte) = (i32x4_splat(0xFF), i32x4_splat(0xFF_0000));
    let mut acc = i32x4_splat(128);
    for (r, w_row) in wy.into_iter().enumerate() {
        let at = v128_and(i32x4_add(at, i32x4_splat(r as i32 * g.stride)), t.valid);
        let mut p = zero;
        macro_rules! row {
            ($l:literal) => {{
                let q = base.add(i32x4_extract_lane::<$l>(at) as usize) as *const u32;
                p = v128_load32_lane::<$l>(p, q);
            }};
        }
        row!(0);
        row!(1);
        row!(2);
        row!(3);
        // Bytes 0, 1 and 2, 3 of each lane as 16-bit pairs.
        let p01 = v128_or(v128_and(p, byte), v128_and(i32x4_shl(p, 8), hi_byte));
        let p23 = v128_or(
            v128_and(u32x4_shr(p, 16), byte),
            v128_and(u32x4_shr(p, 8), hi_byte),
        );
        acc = cubic_row4(acc, p01, p23, wx01, wx23, w_row);
    }
    (cubic_finish4(acc, t.valid), t.valid)
}

/// The bicubic R, G, B samples of four output pixels `u..u + 4` of one
/// interleaved frame (3 or 4 bytes a pixel), whose bilinear footprints are
/// `t`: each lane's four rows of four taps are 32-bit lane loads (a tap's
/// R, G, B and one more byte), each channel's bytes paired to 16 bits and
/// weighted with the 16-bit dot product as [`sample_cubic_gray4`] does; the
/// chunks at the frame's edge go to the scalar reference lane by lane.
#[inline(always)]
unsafe fn sample_cubic_rgb4(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    t: &Taps4,
) -> ([v128; 3], v128) {
    let (x0, y0) = (to_int(t.x0f), to_int(t.y0f));
    let (zero, one) = (i32x4_splat(0), i32x4_splat(1));
    if !cubic_interior4(g, t.valid, x0, y0) {
        let geom = g.scalar();
        return cubic_reference4(coord, u, |sx, sy| geom.sample(data, sx, sy));
    }
    let CubicWeights4 { wx01, wx23, wy } = CubicWeights4::of(t);
    let c = g.channels as usize;
    // Tap (x0 - 1, y0 - 1) of every lane inside the frame.
    let at = i32x4_add(
        i32x4_mul(i32x4_sub(y0, one), i32x4_splat(g.stride)),
        i32x4_mul(i32x4_sub(x0, one), i32x4_splat(g.channels)),
    );
    let base = data.as_ptr();
    let (byte, hi_byte) = (i32x4_splat(0xFF), i32x4_splat(0xFF_0000));
    let mut acc = [i32x4_splat(128); 3];
    for (r, w_row) in wy.into_iter().enumerate() {
        let at = v128_and(i32x4_add(at, i32x4_splat(r as i32 * g.stride)), t.valid);
        let mut p = [zero; 4];
        macro_rules! taps {
            ($l:literal) => {{
                let q = base.add(i32x4_extract_lane::<$l>(at) as usize);
                for (i, p) in p.iter_mut().enumerate() {
                    *p = v128_load32_lane::<$l>(*p, q.add(i * c) as *const u32);
                }
            }};
        }
        taps!(0);
        taps!(1);
        taps!(2);
        taps!(3);
        // Channel byte `shift / 8` of two taps as a 16-bit pair, the first
        // tap's low.
        macro_rules! channel {
            ($c:expr, $shift:expr, $up:expr) => {{
                let p01 = v128_or(
                    v128_and(u32x4_shr(p[0], $shift), byte),
                    v128_and(i32x4_shl(p[1], $up), hi_byte),
                );
                let p23 = v128_or(
                    v128_and(u32x4_shr(p[2], $shift), byte),
                    v128_and(i32x4_shl(p[3], $up), hi_byte),
                );
                acc[$c] = cubic_row4(acc[$c], p01, p23, wx01, wx23, w_row);
            }};
        }
        channel!(0, 0, 16);
        channel!(1, 8, 8);
        channel!(2, 16, 0);
    }
    (acc.map(|a| cubic_finish4(a, t.valid)), t.valid)
}

/// Whether every lane of `valid` (inside the frame) has all its bicubic taps
/// inside it (`1 <= x0 < max_x0`, `1 <= y0 < max_y0`): the vector samplers'
/// case; a chunk with a lane on the frame's one-pixel edge band takes the
/// reference.
#[inline(always)]
fn cubic_interior4(g: &KernelGeometry, valid: v128, x0: v128, y0: v128) -> bool {
    let zero = i32x4_splat(0);
    let inside =
        |p0: v128, max0: i32| v128_and(i32x4_gt(p0, zero), i32x4_lt(p0, i32x4_splat(max0)));
    let interior = v128_and(inside(x0, g.max_x0), inside(y0, g.max_y0));
    !v128_any_true(v128_andnot(valid, interior))
}

/// The reference's samples of the four points `u..u + 4` (`sample`: the
/// scalar sampler of `C` channels) and the lanes inside the frame: a chunk
/// the vector samplers leave (a lane on the frame's edge band).
#[inline(always)]
unsafe fn cubic_reference4<const C: usize>(
    coord: &RowCoords<'_>,
    u: usize,
    sample: impl Fn(f32, f32) -> Option<[u32; C]>,
) -> ([v128; C], v128) {
    let (mut v, mut m) = ([[0u32; 4]; C], [0i32; 4]);
    for l in 0..4 {
        let (sx, sy) = coord.at(u + l);
        if let Some(s) = sample(sx, sy) {
            for (plane, s) in v.iter_mut().zip(s) {
                plane[l] = s;
            }
            m[l] = -1;
        }
    }
    (
        v.map(|plane| v128_load(plane.as_ptr() as *const v128)),
        v128_load(m.as_ptr() as *const v128),
    )
}

/// The bicubic weights of a chunk as the samplers use them: the horizontal
/// ones as 16-bit pairs for the dot product (`(w0, w1)`, `(w2, w3)`; zero in
/// lanes outside the frame), the vertical ones in 32-bit lanes.
struct CubicWeights4 {
    wx01: v128,
    wx23: v128,
    wy: [v128; 4],
}

impl CubicWeights4 {
    #[inline(always)]
    fn of(t: &Taps4) -> Self {
        let (wx, wy) = (cubic_weights4(t.ax), cubic_weights4(t.ay));
        let low16 = i32x4_splat(0xFFFF);
        let pair =
            |lo: v128, hi: v128| v128_and(v128_or(v128_and(lo, low16), i32x4_shl(hi, 16)), t.valid);
        Self {
            wx01: pair(wx[0], wx[1]),
            wx23: pair(wx[2], wx[3]),
            wy,
        }
    }
}

/// `acc + w_row (w0 p0 + w1 p1 + w2 p2 + w3 p3)` for one row of taps given
/// as the 16-bit pairs `p01 = (p0, p1)`, `p23 = (p2, p3)`.
#[inline(always)]
fn cubic_row4(acc: v128, p01: v128, p23: v128, wx01: v128, wx23: v128, w_row: v128) -> v128 {
    let along = i32x4_add(i32x4_dot_i16x8(p01, wx01), i32x4_dot_i16x8(p23, wx23));
    i32x4_add(acc, i32x4_mul(along, w_row))
}

/// A bicubic sum (rounding included) to the reference's 8.8 sample: `>> 8`,
/// clamped to `0..=255 * 256` (the cubic overshoots at edges), 0 outside `valid`.
#[inline(always)]
fn cubic_finish4(acc: v128, valid: v128) -> v128 {
    let v = i32x4_min(
        i32x4_max(i32x4_shr(acc, 8), i32x4_splat(0)),
        i32x4_splat(255 * 256),
    );
    v128_and(v, valid)
}

/// `common::cubic_weights` of four 8-bit fractions, lane by lane.
#[inline(always)]
fn cubic_weights4(a: v128) -> [v128; 4] {
    let mul = |x: v128, k: i32| i32x4_mul(x, i32x4_splat(k));
    let (a2, half) = (i32x4_mul(a, a), i32x4_splat(1 << 16));
    let a3 = i32x4_mul(a2, a);
    let sum = |terms: [v128; 3]| {
        let s = i32x4_add(i32x4_add(terms[0], terms[1]), terms[2]);
        i32x4_shr(i32x4_add(s, half), 17)
    };
    let zero = i32x4_splat(0);
    let w0 = sum([i32x4_sub(zero, a3), mul(a2, 512), mul(a, -65536)]);
    let w2 = sum([mul(a3, -3), mul(a2, 1024), mul(a, 65536)]);
    let w3 = sum([a3, mul(a2, -256), zero]);
    let w1 = i32x4_sub(i32x4_splat(256), i32x4_add(i32x4_add(w0, w2), w3));
    [w0, w1, w2, w3]
}

/// [`Taps4`] as a plane's kernel uses them: where each lane's top-left tap
/// is in the plane and its weights; the same for every plane of one geometry.
struct PlaneTaps4 {
    valid: v128,
    index: v128,
    stride: usize,
    /// `bx` in the low 16 bits of each lane, `ax` in the high ones (0 in
    /// lanes outside the plane, whose samples then come out 0).
    wx: v128,
    ay: v128,
    by: v128,
}

impl PlaneTaps4 {
    #[inline(always)]
    unsafe fn of(g: &KernelGeometry, t: Taps4) -> Self {
        let small_frame = (g.max_y0 as i64 * g.stride as i64 + g.max_x0 as i64) < (1 << 23);
        let index = if small_frame {
            to_int(f32x4_add(
                f32x4_mul(t.y0f, f32x4_splat(g.stride as f32)),
                t.x0f,
            ))
        } else {
            i32x4_add(
                i32x4_mul(to_int(t.y0f), i32x4_splat(g.stride)),
                to_int(t.x0f),
            )
        };
        Self {
            valid: t.valid,
            index,
            stride: g.stride as usize,
            wx: v128_and(v128_or(t.bx, i32x4_shl(t.ax, 16)), t.valid),
            ay: t.ay,
            by: t.by,
        }
    }

    /// The samples of `data`: each lane's two pairs of taps loaded, their
    /// (left, right) bytes spread to 16-bit lanes, then the dot product with
    /// (bx, ax).
    #[inline(always)]
    unsafe fn sample(&self, data: &[u8]) -> v128 {
        let (base, s) = (data.as_ptr(), self.stride);
        // Lane `l`'s pair of taps goes from memory straight into the 16-bit
        // lane `l` (`v128.load16_lane`: no trip through a general register),
        // so the low 8 bytes hold the four pairs in order and one zero
        // extension spreads each pair's (left, right) taps over the 16-bit
        // halves of the 32-bit lane `l`.
        let (mut top, mut bot) = (i32x4_splat(0), i32x4_splat(0));
        macro_rules! taps {
            ($l:literal) => {{
                let p = base.add(i32x4_extract_lane::<$l>(self.index) as usize) as *const u16;
                top = v128_load16_lane::<$l>(top, p);
                bot = v128_load16_lane::<$l>(bot, (p as *const u8).add(s) as *const u16);
            }};
        }
        taps!(0);
        taps!(1);
        taps!(2);
        taps!(3);
        let top = i32x4_dot_i16x8(u16x8_extend_low_u8x16(top), self.wx);
        let bot = i32x4_dot_i16x8(u16x8_extend_low_u8x16(bot), self.wx);
        u32x4_shr(
            i32x4_add(
                i32x4_add(i32x4_mul(top, self.by), i32x4_mul(bot, self.ay)),
                i32x4_splat(128),
            ),
            8,
        )
    }
}

/// Source coordinates of output pixels `u..u + 4` of one frame's row: loaded
/// from its table, or evaluated from its homography exactly as the scalar
/// formula does (no FMA, same operation order: bit-exact).
#[inline(always)]
unsafe fn row_coords4(coord: &RowCoords<'_>, u: usize) -> (v128, v128) {
    match *coord {
        RowCoords::Table(xs, ys) => (
            v128_load(xs.as_ptr().add(u) as *const v128),
            v128_load(ys.as_ptr().add(u) as *const v128),
        ),
        RowCoords::Homography {
            x0,
            y0,
            z0,
            dx,
            dy,
            dz,
        } => {
            let uf = f32x4_add(f32x4_splat(u as f32), f32x4(0.0, 1.0, 2.0, 3.0));
            let z = f32x4_add(f32x4_splat(z0), f32x4_mul(f32x4_splat(dz), uf));
            let iz = v128_bitselect(
                f32x4_div(f32x4_splat(1.0), z),
                f32x4_splat(f32::NAN),
                f32x4_gt(z, f32x4_splat(1e-6)),
            );
            let x = f32x4_add(f32x4_splat(x0), f32x4_mul(f32x4_splat(dx), uf));
            let y = f32x4_add(f32x4_splat(y0), f32x4_mul(f32x4_splat(dy), uf));
            (f32x4_mul(x, iz), f32x4_mul(y, iz))
        }
    }
}

/// The bilinear footprint of four sample points: which lanes fall inside the
/// frame (`valid`), the top-left tap `(x0f, y0f)` of each (integral floats),
/// and the 8-bit weights `ax = round(256 fx)`, `bx = 256 - ax` (and `ay`,
/// `by`) the scalar reference uses.
struct Taps4 {
    valid: v128,
    x0f: v128,
    y0f: v128,
    ax: v128,
    ay: v128,
    bx: v128,
    by: v128,
}

/// [`Taps4`] of the points `(sx, sy)` in a frame of geometry `g`; `None`
/// when no lane is inside (NaN compares false: NaN points are outside).
#[inline(always)]
unsafe fn taps4(g: &KernelGeometry, (sx, sy): (v128, v128)) -> Option<Taps4> {
    let lo = f32x4_splat(-EDGE_TOLERANCE);
    let valid = v128_and(
        v128_and(f32x4_ge(sx, lo), f32x4_ge(sy, lo)),
        v128_and(
            f32x4_le(sx, f32x4_splat(g.max_x + EDGE_TOLERANCE)),
            f32x4_le(sy, f32x4_splat(g.max_y + EDGE_TOLERANCE)),
        ),
    );
    if !v128_any_true(valid) {
        return None;
    }
    // Every lane is clamped onto the frame: valid ones by at most the edge
    // tolerance; NaN lanes go to 0 (`pmax(0, NaN)` is its first operand).
    // Invalid lanes thus read taps inside the frame, and their weights are
    // masked by the callers (`wx`), so they sample 0.
    let zero = f32x4_splat(0.0);
    let sxv = f32x4_pmin(f32x4_pmax(zero, sx), f32x4_splat(g.max_x));
    let syv = f32x4_pmin(f32x4_pmax(zero, sy), f32x4_splat(g.max_y));
    // x0 = min(trunc(sx), max_x0) as in the scalar `(sx as usize).min(max_x0)`.
    let x0f = f32x4_pmin(f32x4_trunc(sxv), f32x4_splat(g.max_x0 as f32));
    let y0f = f32x4_pmin(f32x4_trunc(syv), f32x4_splat(g.max_y0 as f32));
    let (c256, half) = (f32x4_splat(256.0), f32x4_splat(0.5));
    let ax = to_int(f32x4_trunc(f32x4_add(
        f32x4_mul(f32x4_sub(sxv, x0f), c256),
        half,
    )));
    let ay = to_int(f32x4_trunc(f32x4_add(
        f32x4_mul(f32x4_sub(syv, y0f), c256),
        half,
    )));
    let i256 = i32x4_splat(256);
    Some(Taps4 {
        valid,
        x0f,
        y0f,
        ax,
        ay,
        bx: i32x4_sub(i256, ax),
        by: i32x4_sub(i256, ay),
    })
}

/// An integral float `t` in `[0, 2^23)` as an integer: the bits of
/// `t + 2^23` are `0x4B00_0000 + t` (cheaper than the saturating conversion).
#[inline(always)]
fn to_int(t: v128) -> v128 {
    i32x4_sub(
        f32x4_add(t, f32x4_splat(8_388_608.0)),
        i32x4_splat(0x4B00_0000),
    )
}
