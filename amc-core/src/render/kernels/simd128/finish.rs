//! The row finishers: a row's sums into output bytes.

use core::arch::wasm32::*;

/// `1 / (256 n)` per lane (infinite where `n = 0`): the finishers' scale.
#[inline(always)]
unsafe fn scale_of(n: v128) -> v128 {
    f32x4_div(
        f32x4_splat(1.0),
        f32x4_mul(f32x4_splat(256.0), f32x4_convert_i32x4(n)),
    )
}

/// The scalar `(sum as f32 * k + 0.5) as u8` per lane for `sum < 2^24` (exact
/// as f32; the rounded values are integral and in 0..=255, NaN where `k` is
/// infinite, which the caller masks).
#[inline(always)]
unsafe fn round_scaled(sum: v128, k: v128) -> v128 {
    let x = f32x4_convert_i32x4(sum);
    let t = f32x4_trunc(f32x4_add(f32x4_mul(x, k), f32x4_splat(0.5)));
    let v = i32x4_sub(
        f32x4_add(t, f32x4_splat(8_388_608.0)),
        i32x4_splat(0x4B00_0000),
    );
    i32x4_min(v, i32x4_splat(255))
}

/// Finishes `n8` pixels (a multiple of 4) of an RGBA output row from the
/// kernel's sums: `round(sum / (256 n))` per channel, alpha 255, exactly the
/// scalar `(sum as f32 * (1 / (256 n)) + 0.5) as u8` (0 where `n = 0`).
///
/// # Safety
/// The sums must hold at least `n8` values and `out` at least `4 * n8` bytes.
pub(crate) unsafe fn finish_row_rgba(
    acc_r: &[u32],
    acc_g: &[u32],
    acc_b: &[u32],
    count: &[u32],
    out: &mut [u8],
    n8: usize,
) {
    debug_assert!(n8 % 4 == 0 && out.len() >= 4 * n8);
    let alpha = i32x4_splat(0xFF00_0000_u32 as i32);
    let zero = i32x4_splat(0);
    let mut u = 0;
    while u < n8 {
        let n = v128_load(count.as_ptr().add(u) as *const v128);
        let k = scale_of(n);
        let covered = i32x4_ne(n, zero);
        // Sums are below 2^24 (64 frames of 255 * 256); NaN where n = 0, masked.
        let ch =
            |p: *const u32| v128_and(round_scaled(v128_load(p.add(u) as *const v128), k), covered);
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

/// Finishes `n8` pixels (a multiple of 4) of a single-channel output row (a
/// plane of a planar frame) from the kernel's sums, as the scalar pass in the
/// warper does: `(sum as f32 * (1 / (256 n)) + 0.5) as u8`, `fill` where
/// `n = 0`, the coverage `n` as a byte; returns the pixels whose count is `full`.
/// (The scalar pass did not vectorize in V8; see
/// `docs/core-history.md#render-simd128-finish-gray`.)
///
/// # Safety
/// `sum` and `count` must hold at least `n8` values, `out` and `coverage` at
/// least `n8` bytes.
pub(crate) unsafe fn finish_row_gray(
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
        // Sums are below 2^24 (64 frames of 255 * 256); NaN where n = 0,
        // replaced by `fill`.
        let v = round_scaled(v128_load(sum.as_ptr().add(u) as *const v128), scale_of(n));
        let v = v128_bitselect(fill, v, i32x4_eq(n, zero));
        v128_store32_lane::<0>(bytes(v), out.as_mut_ptr().add(u) as *mut u32);
        v128_store32_lane::<0>(bytes(n), coverage.as_mut_ptr().add(u) as *mut u32);
        complete += i32x4_bitmask(i32x4_eq(n, full)).count_ones() as usize;
        u += 4;
    }
    complete
}
