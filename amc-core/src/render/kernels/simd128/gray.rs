//! Planes of planar frames, bilinear: the sums of several frames along a
//! row (one plane, or a pair of one geometry), plain and ghost-free.

use super::super::common::{KernelGeometry, RowCoords};
use super::cubic::sample_cubic_gray4;
use super::taps::{row_coords4, taps4, weights4, PlaneTaps4};
use crate::render::robust::{Deghost, FULL_WEIGHT};
use core::arch::wasm32::*;

/// The single-channel twin of [`accumulate_row`](super::rgb::accumulate_row)
/// for the planes of planar frames: four output pixels at a time, frame-outer;
/// each lane's taps are two 16-bit loads (a tap and its right neighbour, in the
/// row and the row below). Bit-exact with the scalar `accumulate_row_gray`.
///
/// # Safety Every `datas[f]` must hold the whole plane plus 2 readable bytes
/// ([`FRAME_PADDING`](super::super::FRAME_PADDING) covers it); coordinate
/// tables and the outputs must have at least `n8` elements (`n8` a multiple of
/// 4).
pub(crate) unsafe fn accumulate_row_gray(
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
pub(crate) unsafe fn accumulate_row_gray_pair(
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
pub(super) unsafe fn sample_gray4(
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

/// The single-channel twin of [`merge_row`](super::rgb::merge_row) (reference:
/// `scalar::merge_row_gray`).
///
/// # Safety
/// As [`accumulate_row_gray`], and `datas` must not be empty.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn merge_row_gray(
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
