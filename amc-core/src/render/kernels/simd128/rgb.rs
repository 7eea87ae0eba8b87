//! Interleaved frames (RGB, RGBA), bilinear: the sums of several frames
//! along a row, plain and ghost-free.

use super::super::common::{KernelGeometry, RowCoords};
use super::cubic::sample_cubic_rgb4;
use super::taps::{row_coords4, taps4, to_int, weights4, Taps4};
use crate::render::robust::{Deghost, FULL_WEIGHT};
use core::arch::wasm32::*;

/// The WebAssembly `simd128` twin of the AVX2 kernel (`avx2.rs`): four output
/// pixels at a time, one frame after the other. WebAssembly has no gathers, so
/// each lane's taps are read one lane at a time, straight into the lane (an
/// RGBA pixel and its right neighbour in one 8-byte `load64_lane`; lanes
/// outside the frame read offset 0 and are masked off). Float-to-int
/// conversions of the (non-negative, integral) coordinates use the `2^23` trick
/// instead of the slow saturating conversion; the interpolation is the same 8.8
/// fixed-point integer arithmetic (`i32x4.dot_i16x8_s` plays `vpmaddwd`),
/// bit-exact with the scalar reference in `scalar.rs`.
///
/// # Safety Every `datas[f]` must be non-empty and hold the whole frame plus
/// [`FRAME_PADDING`](super::super::FRAME_PADDING) bytes; coordinate tables and
/// the outputs must have at least `n8` elements (`n8` a multiple of 4).
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn accumulate_row(
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
pub(super) unsafe fn sample_rgb4(
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

/// The ghost-free twin of [`accumulate_row`] (reference: `scalar::merge_row`):
/// four pixels at a time, frame-inner (the last frame's samples stay in
/// registers while the others are weighted against them).
///
/// # Safety
/// As [`accumulate_row`], and `datas` must not be empty.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn merge_row(
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
