//! A row's source coordinates, four lanes at a time, and their bilinear
//! taps and weights; the ghost-free weights.

use super::super::common::{KernelGeometry, RowCoords, EDGE_TOLERANCE};
use crate::render::robust::{Deghost, FULL_WEIGHT};
use core::arch::wasm32::*;

/// Source coordinates of output pixels `u..u + 4` of one frame's row: loaded
/// from its table, or evaluated from its homography exactly as the scalar
/// formula does (no FMA, same operation order: bit-exact).
#[inline(always)]
pub(super) unsafe fn row_coords4(coord: &RowCoords<'_>, u: usize) -> (v128, v128) {
    match *coord {
        RowCoords::Table(xs, ys) => (
            v128_load(xs.as_ptr().add(u) as *const v128),
            v128_load(ys.as_ptr().add(u) as *const v128),
        ),
        RowCoords::Homography(h) => {
            let uf = f32x4_add(f32x4_splat(u as f32), f32x4(0.0, 1.0, 2.0, 3.0));
            let z = f32x4_add(f32x4_splat(h.z0), f32x4_mul(f32x4_splat(h.dz), uf));
            let iz = v128_bitselect(
                f32x4_div(f32x4_splat(1.0), z),
                f32x4_splat(f32::NAN),
                f32x4_gt(z, f32x4_splat(1e-6)),
            );
            let x = f32x4_add(f32x4_splat(h.x0), f32x4_mul(f32x4_splat(h.dx), uf));
            let y = f32x4_add(f32x4_splat(h.y0), f32x4_mul(f32x4_splat(h.dy), uf));
            (f32x4_mul(x, iz), f32x4_mul(y, iz))
        }
    }
}

/// The bilinear footprint of four sample points: which lanes fall inside the
/// frame (`valid`), the top-left tap `(x0f, y0f)` of each (integral floats),
/// and the 8-bit weights `ax = round(256 fx)`, `bx = 256 - ax` (and `ay`,
/// `by`) the scalar reference uses.
pub(super) struct Taps4 {
    pub(super) valid: v128,
    pub(super) x0f: v128,
    pub(super) y0f: v128,
    pub(super) ax: v128,
    pub(super) ay: v128,
    pub(super) bx: v128,
    pub(super) by: v128,
}

/// [`Taps4`] of the points `(sx, sy)` in a frame of geometry `g`; `None`
/// when no lane is inside (NaN compares false: NaN points are outside).
#[inline(always)]
pub(super) unsafe fn taps4(g: &KernelGeometry, (sx, sy): (v128, v128)) -> Option<Taps4> {
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

/// [`Taps4`] as a plane's kernel uses them: where each lane's top-left tap
/// is in the plane and its weights; the same for every plane of one geometry.
pub(super) struct PlaneTaps4 {
    pub(super) valid: v128,
    pub(super) index: v128,
    pub(super) stride: usize,
    /// `bx` in the low 16 bits of each lane, `ax` in the high ones (0 in
    /// lanes outside the plane, whose samples then come out 0).
    pub(super) wx: v128,
    pub(super) ay: v128,
    pub(super) by: v128,
}

impl PlaneTaps4 {
    #[inline(always)]
    pub(super) unsafe fn of(g: &KernelGeometry, t: Taps4) -> Self {
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
    pub(super) unsafe fn sample(&self, data: &[u8]) -> v128 {
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

/// An integral float `t` in `[0, 2^23)` as an integer: the bits of
/// `t + 2^23` are `0x4B00_0000 + t` (cheaper than the saturating conversion).
#[inline(always)]
pub(super) fn to_int(t: v128) -> v128 {
    i32x4_sub(
        f32x4_add(t, f32x4_splat(8_388_608.0)),
        i32x4_splat(0x4B00_0000),
    )
}

/// The ghost-free weights of four samples differing by `d` from the
/// reference's: `Deghost::weight` lane by lane (`d <= 65280`), 16 where the
/// reference does not cover the pixel (`reference` lanes clear), 0 where the
/// frame does not (`valid` clear).
#[inline(always)]
pub(super) fn weights4(deghost: Deghost, d: v128, reference: v128, valid: v128) -> v128 {
    let (zero_at, slope) = deghost.constants();
    let full = i32x4_splat(FULL_WEIGHT as i32);
    let ramp = i32x4_max(i32x4_sub(i32x4_splat(zero_at), d), i32x4_splat(0));
    let w = i32x4_min(u32x4_shr(i32x4_mul(ramp, i32x4_splat(slope)), 16), full);
    v128_and(v128_bitselect(w, full, reference), valid)
}
