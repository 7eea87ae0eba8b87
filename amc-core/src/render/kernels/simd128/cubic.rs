//! Bicubic sampling, planes and interleaved frames.

use super::super::common::{KernelGeometry, RowCoords};
use super::taps::{to_int, Taps4};
use core::arch::wasm32::*;

/// The bicubic samples of four output pixels `u..u + 4` of one plane, whose
/// bilinear footprints are `t` (see `common::cubic_weights`), as the AVX2
/// kernel's `sample_cubic_gray8`: each lane's four tap rows are four 32-bit
/// lane loads, their bytes spread to 16-bit pairs for `i32x4.dot_i16x8_s`,
/// the rows weighted in 32-bit lanes; a chunk with a lane at the plane's edge
/// goes to the scalar reference. Lanes outside the plane read its first bytes
/// (offset 0 plus nothing: no tap row below it is read) with zero weights.
#[inline(always)]
pub(super) unsafe fn sample_cubic_gray4(
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
pub(super) unsafe fn sample_cubic_rgb4(
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
pub(super) fn cubic_interior4(g: &KernelGeometry, valid: v128, x0: v128, y0: v128) -> bool {
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
pub(super) unsafe fn cubic_reference4<const C: usize>(
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
pub(super) struct CubicWeights4 {
    pub(super) wx01: v128,
    pub(super) wx23: v128,
    pub(super) wy: [v128; 4],
}

impl CubicWeights4 {
    #[inline(always)]
    pub(super) fn of(t: &Taps4) -> Self {
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
pub(super) fn cubic_row4(
    acc: v128,
    p01: v128,
    p23: v128,
    wx01: v128,
    wx23: v128,
    w_row: v128,
) -> v128 {
    let along = i32x4_add(i32x4_dot_i16x8(p01, wx01), i32x4_dot_i16x8(p23, wx23));
    i32x4_add(acc, i32x4_mul(along, w_row))
}

/// A bicubic sum (rounding included) to the reference's 8.8 sample: `>> 8`,
/// clamped to `0..=255 * 256` (the cubic overshoots at edges), 0 outside `valid`.
#[inline(always)]
pub(super) fn cubic_finish4(acc: v128, valid: v128) -> v128 {
    let v = i32x4_min(
        i32x4_max(i32x4_shr(acc, 8), i32x4_splat(0)),
        i32x4_splat(255 * 256),
    );
    v128_and(v, valid)
}

/// `common::cubic_weights` of four 8-bit fractions, lane by lane.
#[inline(always)]
pub(super) fn cubic_weights4(a: v128) -> [v128; 4] {
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
