//! The x86-64 AVX2 row kernel (used when the CPU has AVX2).
//!
//! Eight output pixels at a time: coordinates, weights and byte offsets are
//! computed in 32-bit lanes, the four bilinear taps are fetched with masked
//! 32-bit gathers (one dword holds a pixel's R, G, B), and the 8.8 fixed-point
//! interpolation is done per channel in integer lanes, bit-exact with the
//! scalar reference in `scalar.rs`. Lanes whose coordinate falls outside the
//! frame are masked off and contribute nothing. Planes sampled bicubically
//! take four gathers a pixel, one per tap row (`sample_cubic_gray8`), and
//! interleaved frames sixteen, one per tap (`sample_cubic_rgb8`).

pub(super) use super::avx2_merge::{merge_row, merge_row_gray, merge_row_gray_pair};
use super::avx2_window::Window8;
use super::common::{falls, KernelGeometry, RowCoords, EDGE_TOLERANCE};
use std::arch::x86_64::*;

/// Accumulates the samples of several frames along one output row: for
/// `u in 0..n8` (a multiple of 8), `acc_{r,g,b}[u] = sum_f sample_f(xs[f][u], ys[f][u])`
/// and `count[u]` = frames whose coordinate lies inside the frame. Accumulators
/// stay in registers across frames; each chunk of 8 pixels is stored once.
///
/// # Safety
/// The CPU must support AVX2 ([`super::avx2_available`]); every `datas[f]` must hold
/// the whole frame plus [`super::FRAME_PADDING`] bytes; coordinate tables and the
/// outputs must have at least `n8` elements.
#[target_feature(enable = "avx2")]
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
    debug_assert!(n8 & 7 == 0 && datas.len() == coords.len());
    debug_assert!(acc_r.len() >= n8 && acc_g.len() >= n8 && acc_b.len() >= n8 && count.len() >= n8);
    let one = _mm256_set1_epi32(1);
    let mut u = 0;
    while u < n8 {
        let (mut sum_r, mut sum_g, mut sum_b, mut sum_n) = (
            _mm256_setzero_si256(),
            _mm256_setzero_si256(),
            _mm256_setzero_si256(),
            _mm256_setzero_si256(),
        );
        for (data, coord) in datas.iter().zip(coords) {
            let Some(([r, gg, b], mask)) = sample_rgb8(data, &g, coord, u) else {
                continue;
            };
            sum_r = _mm256_add_epi32(sum_r, r);
            sum_g = _mm256_add_epi32(sum_g, gg);
            sum_b = _mm256_add_epi32(sum_b, b);
            sum_n = _mm256_add_epi32(sum_n, _mm256_and_si256(mask, one));
        }
        _mm256_storeu_si256(acc_r.as_mut_ptr().add(u) as *mut __m256i, sum_r);
        _mm256_storeu_si256(acc_g.as_mut_ptr().add(u) as *mut __m256i, sum_g);
        _mm256_storeu_si256(acc_b.as_mut_ptr().add(u) as *mut __m256i, sum_b);
        _mm256_storeu_si256(count.as_mut_ptr().add(u) as *mut __m256i, sum_n);
        u += 8;
    }
}

/// The 8.8 fixed-point R, G, B samples of eight output pixels `u..u + 8` of one
/// frame (0 in lanes outside it) and the lanes inside it (all bits set); `None`
/// when no lane is inside.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn sample_rgb8(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
) -> Option<([__m256i; 3], __m256i)> {
    let stride = _mm256_set1_epi32(g.stride);
    let chans = _mm256_set1_epi32(g.channels);
    let i128 = _mm256_set1_epi32(128);
    let byte = _mm256_set1_epi32(0xFF);
    // Byte 2 of each lane (bits 16..24): where the right-hand tap goes.
    let hi_byte = _mm256_set1_epi32(0xFF_0000);
    let base = data.as_ptr() as *const i32;
    let t = taps8(g, row_coords8(coord, u))?;
    if g.cubic {
        return Some(sample_cubic_rgb8(data, g, coord, u, &t));
    }
    let Taps8 {
        mask,
        x0,
        y0,
        ax,
        ay,
        bx,
        by,
    } = t;
    let i00 = _mm256_add_epi32(
        _mm256_mullo_epi32(y0, stride),
        _mm256_mullo_epi32(x0, chans),
    );
    let i01 = _mm256_add_epi32(i00, chans);
    let i10 = _mm256_add_epi32(i00, stride);
    let i11 = _mm256_add_epi32(i10, chans);
    let z = _mm256_setzero_si256();
    let p00 = _mm256_mask_i32gather_epi32::<1>(z, base, i00, mask);
    let p01 = _mm256_mask_i32gather_epi32::<1>(z, base, i01, mask);
    let p10 = _mm256_mask_i32gather_epi32::<1>(z, base, i10, mask);
    let p11 = _mm256_mask_i32gather_epi32::<1>(z, base, i11, mask);
    // Horizontal step with one madd per row: lanes hold the 16-bit pairs
    // (left, right) and (bx, ax), so madd gives left*bx + right*ax.
    let wx = _mm256_or_si256(bx, _mm256_slli_epi32::<16>(ax));
    macro_rules! channel {
        ($shift:expr, $up:expr) => {{
            let top = _mm256_or_si256(
                _mm256_and_si256(_mm256_srli_epi32::<$shift>(p00), byte),
                _mm256_and_si256(_mm256_slli_epi32::<$up>(p01), hi_byte),
            );
            let bot = _mm256_or_si256(
                _mm256_and_si256(_mm256_srli_epi32::<$shift>(p10), byte),
                _mm256_and_si256(_mm256_slli_epi32::<$up>(p11), hi_byte),
            );
            let top = _mm256_madd_epi16(top, wx);
            let bot = _mm256_madd_epi16(bot, wx);
            let v = _mm256_add_epi32(
                _mm256_add_epi32(_mm256_mullo_epi32(top, by), _mm256_mullo_epi32(bot, ay)),
                i128,
            );
            _mm256_and_si256(_mm256_srli_epi32::<8>(v), mask)
        }};
    }
    Some(([channel!(0, 16), channel!(8, 8), channel!(16, 0)], mask))
}

/// The 8.8 fixed-point samples of eight output pixels `u..u + 8` of one plane
/// (0 in lanes outside it) and the lanes inside it; `None` when no lane is inside.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn sample_gray8(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
) -> Option<(__m256i, __m256i)> {
    let t = taps8(g, row_coords8(coord, u))?;
    if g.cubic {
        return Some(sample_cubic_gray8(data, g, coord, u, &t));
    }
    let t = PlaneTaps8::of(g, t, falls(coord, u));
    Some((t.sample(data), t.mask))
}

/// The bicubic samples of eight output pixels `u..u + 8` of one plane, whose
/// bilinear footprints are `t` (see `common::cubic_weights`): each lane's four
/// rows of four taps are four dword gathers, their bytes spread to 16-bit
/// pairs and weighted with `madd`, the rows then weighted in 32-bit lanes;
/// exact integers throughout, rounded and clamped as the reference does. A
/// chunk with a lane whose taps would cross the plane's edge (`x0` or `y0` on
/// the first or last tap) is left to the scalar reference, which repeats the
/// edge pixel: those lie in a band one pixel wide around the plane. Not
/// inlined: the bilinear path it branches off from is, into every row loop.
#[target_feature(enable = "avx2")]
#[inline(never)]
unsafe fn sample_cubic_gray8(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    t: &Taps8,
) -> (__m256i, __m256i) {
    let (zero, one) = (_mm256_setzero_si256(), _mm256_set1_epi32(1));
    if !cubic_interior8(g, t) {
        let geom = g.scalar();
        let ([v], m) = cubic_reference8(coord, u, |sx, sy| {
            geom.sample_gray(data, sx, sy).map(|v| [v])
        });
        return (v, m);
    }
    let CubicWeights8 { wx01, wx23, wy } = CubicWeights8::of(t);
    let stride = _mm256_set1_epi32(g.stride);
    // Tap (x0 - 1, y0 - 1) of every lane.
    let mut at = _mm256_add_epi32(
        _mm256_mullo_epi32(_mm256_sub_epi32(t.y0, one), stride),
        _mm256_sub_epi32(t.x0, one),
    );
    let base = data.as_ptr() as *const i32;
    let (byte, hi_byte) = (_mm256_set1_epi32(0xFF), _mm256_set1_epi32(0xFF_0000));
    let mut acc = _mm256_set1_epi32(128);
    for w_row in wy {
        let p = _mm256_mask_i32gather_epi32::<1>(zero, base, at, t.mask);
        // Bytes 0, 1 and 2, 3 of each dword as 16-bit pairs.
        let p01 = _mm256_or_si256(
            _mm256_and_si256(p, byte),
            _mm256_and_si256(_mm256_slli_epi32::<8>(p), hi_byte),
        );
        let p23 = _mm256_or_si256(
            _mm256_and_si256(_mm256_srli_epi32::<16>(p), byte),
            _mm256_and_si256(_mm256_srli_epi32::<8>(p), hi_byte),
        );
        acc = cubic_row8(acc, p01, p23, wx01, wx23, w_row);
        at = _mm256_add_epi32(at, stride);
    }
    (cubic_finish8(acc, t.mask), t.mask)
}

/// The bicubic R, G, B samples of eight output pixels `u..u + 8` of one
/// interleaved frame (3 or 4 bytes a pixel), whose bilinear footprints are
/// `t`: each lane's four rows of four taps are sixteen dword gathers (a
/// tap's dword holds its R, G, B), each channel's bytes paired to 16 bits and
/// weighted with `madd` as [`sample_cubic_gray8`] does; the chunks at the
/// frame's edge go to the scalar reference lane by lane.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn sample_cubic_rgb8(
    data: &[u8],
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
    t: &Taps8,
) -> ([__m256i; 3], __m256i) {
    let (zero, one) = (_mm256_setzero_si256(), _mm256_set1_epi32(1));
    if !cubic_interior8(g, t) {
        let geom = g.scalar();
        return cubic_reference8(coord, u, |sx, sy| geom.sample(data, sx, sy));
    }
    let CubicWeights8 { wx01, wx23, wy } = CubicWeights8::of(t);
    let (stride, chans) = (_mm256_set1_epi32(g.stride), _mm256_set1_epi32(g.channels));
    // Tap (x0 - 1, y0 - 1) of every lane.
    let mut at = _mm256_add_epi32(
        _mm256_mullo_epi32(_mm256_sub_epi32(t.y0, one), stride),
        _mm256_mullo_epi32(_mm256_sub_epi32(t.x0, one), chans),
    );
    let base = data.as_ptr() as *const i32;
    let (byte, hi_byte) = (_mm256_set1_epi32(0xFF), _mm256_set1_epi32(0xFF_0000));
    let mut acc = [_mm256_set1_epi32(128); 3];
    for w_row in wy {
        let tap = |i: i32| {
            let at = _mm256_add_epi32(at, _mm256_set1_epi32(i * g.channels));
            _mm256_mask_i32gather_epi32::<1>(zero, base, at, t.mask)
        };
        let (p0, p1, p2, p3) = (tap(0), tap(1), tap(2), tap(3));
        // Channel byte `shift / 8` of two taps as a 16-bit pair, the first
        // tap's low: (p_a >> shift) & 0xFF | (p_b << up) & 0xFF0000.
        macro_rules! channel {
            ($c:expr, $shift:expr, $up:expr) => {{
                let p01 = _mm256_or_si256(
                    _mm256_and_si256(_mm256_srli_epi32::<$shift>(p0), byte),
                    _mm256_and_si256(_mm256_slli_epi32::<$up>(p1), hi_byte),
                );
                let p23 = _mm256_or_si256(
                    _mm256_and_si256(_mm256_srli_epi32::<$shift>(p2), byte),
                    _mm256_and_si256(_mm256_slli_epi32::<$up>(p3), hi_byte),
                );
                acc[$c] = cubic_row8(acc[$c], p01, p23, wx01, wx23, w_row);
            }};
        }
        channel!(0, 0, 16);
        channel!(1, 8, 8);
        channel!(2, 16, 0);
        at = _mm256_add_epi32(at, stride);
    }
    (acc.map(|a| cubic_finish8(a, t.mask)), t.mask)
}

/// Whether every lane of `t` inside the frame has all its bicubic taps inside
/// it (`1 <= x0 < max_x0`, `1 <= y0 < max_y0`): the vector samplers' case;
/// a chunk with a lane on the frame's one-pixel edge band takes the reference.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn cubic_interior8(g: &KernelGeometry, t: &Taps8) -> bool {
    let zero = _mm256_setzero_si256();
    let inside = |p0: __m256i, max0: i32| {
        _mm256_and_si256(
            _mm256_cmpgt_epi32(p0, zero),
            _mm256_cmpgt_epi32(_mm256_set1_epi32(max0), p0),
        )
    };
    let interior = _mm256_and_si256(inside(t.x0, g.max_x0), inside(t.y0, g.max_y0));
    _mm256_testc_si256(interior, t.mask) != 0
}

/// The reference's samples of the eight points `u..u + 8` (`sample`: the
/// scalar sampler of `C` channels) and the lanes inside the frame: a chunk
/// the vector samplers leave (a lane on the frame's edge band).
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn cubic_reference8<const C: usize>(
    coord: &RowCoords<'_>,
    u: usize,
    sample: impl Fn(f32, f32) -> Option<[u32; C]>,
) -> ([__m256i; C], __m256i) {
    let (mut v, mut m) = ([[0u32; 8]; C], [0i32; 8]);
    for l in 0..8 {
        let (sx, sy) = coord.at(u + l);
        if let Some(s) = sample(sx, sy) {
            for (plane, s) in v.iter_mut().zip(s) {
                plane[l] = s;
            }
            m[l] = -1;
        }
    }
    (
        v.map(|plane| _mm256_loadu_si256(plane.as_ptr() as *const __m256i)),
        _mm256_loadu_si256(m.as_ptr() as *const __m256i),
    )
}

/// The bicubic weights of a chunk as the samplers use them: the horizontal
/// ones as 16-bit pairs for `madd` (`(w0, w1)`, `(w2, w3)`), the vertical ones
/// in 32-bit lanes.
struct CubicWeights8 {
    wx01: __m256i,
    wx23: __m256i,
    wy: [__m256i; 4],
}

impl CubicWeights8 {
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn of(t: &Taps8) -> Self {
        let (wx, wy) = (cubic_weights8(t.ax), cubic_weights8(t.ay));
        let low16 = _mm256_set1_epi32(0xFFFF);
        let pair = |lo: __m256i, hi: __m256i| {
            _mm256_or_si256(_mm256_and_si256(lo, low16), _mm256_slli_epi32::<16>(hi))
        };
        Self {
            wx01: pair(wx[0], wx[1]),
            wx23: pair(wx[2], wx[3]),
            wy,
        }
    }
}

/// `acc + w_row (w0 p0 + w1 p1 + w2 p2 + w3 p3)` for one row of taps given
/// as the 16-bit pairs `p01 = (p0, p1)`, `p23 = (p2, p3)`.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn cubic_row8(
    acc: __m256i,
    p01: __m256i,
    p23: __m256i,
    wx01: __m256i,
    wx23: __m256i,
    w_row: __m256i,
) -> __m256i {
    let along = _mm256_add_epi32(_mm256_madd_epi16(p01, wx01), _mm256_madd_epi16(p23, wx23));
    _mm256_add_epi32(acc, _mm256_mullo_epi32(along, w_row))
}

/// A bicubic sum (rounding included) to the reference's 8.8 sample: `>> 8`,
/// clamped to `0..=255 * 256` (the cubic overshoots at edges), 0 outside `mask`.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn cubic_finish8(acc: __m256i, mask: __m256i) -> __m256i {
    let v = _mm256_min_epi32(
        _mm256_max_epi32(_mm256_srai_epi32::<8>(acc), _mm256_setzero_si256()),
        _mm256_set1_epi32(255 * 256),
    );
    _mm256_and_si256(v, mask)
}

/// `common::cubic_weights` of eight 8-bit fractions, lane by lane.
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn cubic_weights8(a: __m256i) -> [__m256i; 4] {
    let mul = |x: __m256i, k: i32| _mm256_mullo_epi32(x, _mm256_set1_epi32(k));
    let (a2, half) = (_mm256_mullo_epi32(a, a), _mm256_set1_epi32(1 << 16));
    let a3 = _mm256_mullo_epi32(a2, a);
    let sum = |terms: [__m256i; 3]| {
        let s = _mm256_add_epi32(_mm256_add_epi32(terms[0], terms[1]), terms[2]);
        _mm256_srai_epi32::<17>(_mm256_add_epi32(s, half))
    };
    let w0 = sum([
        _mm256_sub_epi32(_mm256_setzero_si256(), a3),
        mul(a2, 512),
        mul(a, -65536),
    ]);
    let w2 = sum([mul(a3, -3), mul(a2, 1024), mul(a, 65536)]);
    let w3 = sum([a3, mul(a2, -256), _mm256_setzero_si256()]);
    let w1 = _mm256_sub_epi32(
        _mm256_set1_epi32(256),
        _mm256_add_epi32(_mm256_add_epi32(w0, w2), w3),
    );
    [w0, w1, w2, w3]
}

/// [`Taps8`] as a plane's kernel uses them: where each lane's taps lie in
/// the plane (in a [`Window8`] of its rows where they fit, else gathered)
/// and its weights; the same for every plane of one geometry.
pub(super) struct PlaneTaps8 {
    mask: __m256i,
    x0: __m256i,
    y0: __m256i,
    window: Option<Window8>,
    stride: i32,
    /// `bx` in the low 16 bits of each lane, `ax` in the high ones.
    wx: __m256i,
    ay: __m256i,
    by: __m256i,
}

impl PlaneTaps8 {
    /// `falls`: whether the row's `y` falls along it ([`falls`]).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn of(g: &KernelGeometry, t: Taps8, falls: bool) -> Self {
        Self {
            mask: t.mask,
            window: Window8::of(g, t.mask, t.x0, t.y0, falls),
            x0: t.x0,
            y0: t.y0,
            stride: g.stride,
            wx: _mm256_or_si256(t.bx, _mm256_slli_epi32::<16>(t.ax)),
            ay: t.ay,
            by: t.by,
        }
    }

    /// The samples of `data` (0 in lanes outside the mask): each lane's
    /// (left, right) pairs of its two rows as 16-bit words, from the window
    /// or gathered, weighted with `madd`, then the rows in 32-bit lanes.
    #[target_feature(enable = "avx2")]
    #[inline]
    unsafe fn sample(&self, data: &[u8]) -> __m256i {
        let (p0, p1) = self
            .window
            .as_ref()
            .and_then(|w| w.fetch(data, self.stride as usize))
            .unwrap_or_else(|| self.gather_pairs(data));
        let top = _mm256_madd_epi16(p0, self.wx);
        let bot = _mm256_madd_epi16(p1, self.wx);
        let v = _mm256_add_epi32(
            _mm256_add_epi32(
                _mm256_mullo_epi32(top, self.by),
                _mm256_mullo_epi32(bot, self.ay),
            ),
            _mm256_set1_epi32(128),
        );
        _mm256_and_si256(_mm256_srli_epi32::<8>(v), self.mask)
    }

    /// Each lane's (left, right) pairs of its top and bottom row as 16-bit
    /// words, gathered: one dword a lane and row, from the left tap on.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(super) unsafe fn gather_pairs(&self, data: &[u8]) -> (__m256i, __m256i) {
        let stride = _mm256_set1_epi32(self.stride);
        let top = _mm256_add_epi32(_mm256_mullo_epi32(self.y0, stride), self.x0);
        let bottom = _mm256_add_epi32(top, stride);
        let base = data.as_ptr() as *const i32;
        let z = _mm256_setzero_si256();
        let p0 = _mm256_mask_i32gather_epi32::<1>(z, base, top, self.mask);
        let p1 = _mm256_mask_i32gather_epi32::<1>(z, base, bottom, self.mask);
        let (byte, hi_byte) = (_mm256_set1_epi32(0xFF), _mm256_set1_epi32(0xFF_0000));
        let pair = |p: __m256i| {
            _mm256_or_si256(
                _mm256_and_si256(p, byte),
                _mm256_and_si256(_mm256_slli_epi32::<8>(p), hi_byte),
            )
        };
        (pair(p0), pair(p1))
    }
}

/// Source coordinates of output pixels `u..u + 8` of one frame's row: loaded
/// from its table, or evaluated from its homography exactly as the scalar
/// formula does (no FMA, same operation order: bit-exact).
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn row_coords8(coord: &RowCoords<'_>, u: usize) -> (__m256, __m256) {
    match *coord {
        RowCoords::Table(xs, ys) => (
            _mm256_loadu_ps(xs.as_ptr().add(u)),
            _mm256_loadu_ps(ys.as_ptr().add(u)),
        ),
        RowCoords::Homography(h) => {
            let lane = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
            let uf = _mm256_add_ps(_mm256_set1_ps(u as f32), lane);
            let z = _mm256_add_ps(
                _mm256_set1_ps(h.z0),
                _mm256_mul_ps(_mm256_set1_ps(h.dz), uf),
            );
            let iz = _mm256_blendv_ps(
                _mm256_set1_ps(f32::NAN),
                _mm256_div_ps(_mm256_set1_ps(1.0), z),
                _mm256_cmp_ps(z, _mm256_set1_ps(1e-6), _CMP_GT_OQ),
            );
            let x = _mm256_add_ps(
                _mm256_set1_ps(h.x0),
                _mm256_mul_ps(_mm256_set1_ps(h.dx), uf),
            );
            let y = _mm256_add_ps(
                _mm256_set1_ps(h.y0),
                _mm256_mul_ps(_mm256_set1_ps(h.dy), uf),
            );
            (_mm256_mul_ps(x, iz), _mm256_mul_ps(y, iz))
        }
    }
}

/// The single-channel twin of [`accumulate_row`] for the planes of planar
/// frames (Y at full resolution, U and V at theirs): two gathers per pixel and
/// frame instead of four, each dword holding a tap and its right neighbour.
/// For `u in 0..n8` (a multiple of 8), `acc[u] = sum_f sample_f(coords[f] at u)`
/// and `count[u]` = frames whose coordinate lies inside the plane.
///
/// # Safety
/// The CPU must support AVX2; every `datas[f]` must hold the whole plane plus
/// 2 readable bytes ([`super::FRAME_PADDING`] covers it); coordinate tables and
/// the outputs must have at least `n8` elements.
#[target_feature(enable = "avx2")]
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
    let one = _mm256_set1_epi32(1);
    let mut u = 0;
    while u < n8 {
        let (mut sum, mut sum_n) = (_mm256_setzero_si256(), _mm256_setzero_si256());
        for (data, coord) in datas.iter().zip(coords) {
            let Some((v, mask)) = sample_gray8(data, &g, coord, u) else {
                continue;
            };
            sum = _mm256_add_epi32(sum, v);
            sum_n = _mm256_add_epi32(sum_n, _mm256_and_si256(mask, one));
        }
        _mm256_storeu_si256(acc.as_mut_ptr().add(u) as *mut __m256i, sum);
        _mm256_storeu_si256(count.as_mut_ptr().add(u) as *mut __m256i, sum_n);
        u += 8;
    }
}

/// [`accumulate_row_gray`] of two planes of one geometry at once (the U and
/// V planes of 4:2:0 frames): `acc_a` and `acc_b` from `datas_a` and
/// `datas_b`, one `count`; each chunk's coordinates, taps and gather
/// offsets are found once for both planes.
///
/// # Safety
/// As [`accumulate_row_gray`], for both planes' data.
#[target_feature(enable = "avx2")]
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
    let one = _mm256_set1_epi32(1);
    let mut u = 0;
    while u < n8 {
        let z = _mm256_setzero_si256();
        let (mut sum_a, mut sum_b, mut sum_n) = (z, z, z);
        for ((a, b), coord) in datas_a.iter().zip(datas_b).zip(coords) {
            let Some((va, vb, mask)) = sample_pair8((a, b), &g, coord, u) else {
                continue;
            };
            sum_a = _mm256_add_epi32(sum_a, va);
            sum_b = _mm256_add_epi32(sum_b, vb);
            sum_n = _mm256_add_epi32(sum_n, _mm256_and_si256(mask, one));
        }
        _mm256_storeu_si256(acc_a.as_mut_ptr().add(u) as *mut __m256i, sum_a);
        _mm256_storeu_si256(acc_b.as_mut_ptr().add(u) as *mut __m256i, sum_b);
        _mm256_storeu_si256(count.as_mut_ptr().add(u) as *mut __m256i, sum_n);
        u += 8;
    }
}

/// The bilinear samples of output pixels `u..u + 8` in two planes of one
/// geometry, their taps found once, and the lanes inside the planes; `None`
/// where no lane is.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn sample_pair8(
    (a, b): (&[u8], &[u8]),
    g: &KernelGeometry,
    coord: &RowCoords<'_>,
    u: usize,
) -> Option<(__m256i, __m256i, __m256i)> {
    let t = taps8(g, row_coords8(coord, u))?;
    let t = PlaneTaps8::of(g, t, falls(coord, u));
    Some((t.sample(a), t.sample(b), t.mask))
}

/// Finishes the first `n8` pixels (a multiple of 8) of a single-channel output
/// row from [`accumulate_row_gray`]'s sums, eight at a time: the contract of
/// `avx512::finish_row_gray` (`round(sum / (256 n))` as the scalar `average`
/// computes it, `fill` where `n = 0`, `coverage[u] = n`); returns how many
/// pixels `full` frames cover.
///
/// # Safety
/// The CPU must support AVX2; `sum`, `count`, `out` and `coverage` must hold
/// at least `n8` values.
#[target_feature(enable = "avx2")]
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
        _mm256_set1_ps(256.0),
        _mm256_set1_ps(0.5),
        _mm256_set1_ps(1.0),
    );
    let (zero, max) = (_mm256_setzero_si256(), _mm256_set1_epi32(255));
    let (fill, full) = (
        _mm256_set1_epi32(fill as i32),
        _mm256_set1_epi32(full as i32),
    );
    // Byte 0 of each 32-bit lane to the front of its 128-bit half.
    let low_bytes = _mm256_setr_epi8(
        0, 4, 8, 12, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, 0, 4, 8, 12, -1, -1, -1, -1,
        -1, -1, -1, -1, -1, -1, -1, -1,
    );
    let store8 = |dst: *mut u8, v: __m256i| {
        let b = _mm256_shuffle_epi8(v, low_bytes);
        let lo = _mm_cvtsi128_si32(_mm256_castsi256_si128(b)) as u32;
        let hi = _mm_cvtsi128_si32(_mm256_extracti128_si256::<1>(b)) as u32;
        (dst as *mut u32).write_unaligned(lo);
        (dst.add(4) as *mut u32).write_unaligned(hi);
    };
    let mut complete = 0;
    let mut u = 0;
    while u < n8 {
        let s = _mm256_loadu_si256(sum.as_ptr().add(u) as *const __m256i);
        let n = _mm256_loadu_si256(count.as_ptr().add(u) as *const __m256i);
        // As the AVX-512 pass: exact conversions, a correctly rounded
        // division, no FMA; NaN (n = 0) converts to i32::MIN and clamps to 0.
        let r = _mm256_div_ps(one, _mm256_mul_ps(c256, _mm256_cvtepi32_ps(n)));
        let v = _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(s), r), half);
        let v = _mm256_min_epi32(_mm256_max_epi32(_mm256_cvttps_epi32(v), zero), max);
        let empty = _mm256_cmpeq_epi32(n, zero);
        store8(out.as_mut_ptr().add(u), _mm256_blendv_epi8(v, fill, empty));
        store8(coverage.as_mut_ptr().add(u), n);
        let covered = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(n, full)));
        complete += covered.count_ones() as usize;
        u += 8;
    }
    complete
}

/// The bilinear footprint of eight sample points: which lanes fall inside the
/// frame (`mask`, all bits of a lane), the top-left tap `(x0, y0)` of each, and
/// the 8-bit weights `ax = round(256 fx)`, `bx = 256 - ax` (and `ay`, `by`) the
/// scalar reference uses.
pub(super) struct Taps8 {
    pub(super) mask: __m256i,
    pub(super) x0: __m256i,
    pub(super) y0: __m256i,
    ax: __m256i,
    ay: __m256i,
    bx: __m256i,
    by: __m256i,
}

/// [`Taps8`] of the points `(sx, sy)` in a frame of geometry `g`; `None`
/// when no lane is inside (NaN compares false: NaN points are outside).
#[target_feature(enable = "avx2")]
#[inline]
pub(super) unsafe fn taps8(g: &KernelGeometry, (sx, sy): (__m256, __m256)) -> Option<Taps8> {
    let lo = _mm256_set1_ps(-EDGE_TOLERANCE);
    let valid = _mm256_and_ps(
        _mm256_and_ps(
            _mm256_cmp_ps(sx, lo, _CMP_GE_OQ),
            _mm256_cmp_ps(sy, lo, _CMP_GE_OQ),
        ),
        _mm256_and_ps(
            _mm256_cmp_ps(sx, _mm256_set1_ps(g.max_x + EDGE_TOLERANCE), _CMP_LE_OQ),
            _mm256_cmp_ps(sy, _mm256_set1_ps(g.max_y + EDGE_TOLERANCE), _CMP_LE_OQ),
        ),
    );
    let mask = _mm256_castps_si256(valid);
    if _mm256_testz_si256(mask, mask) != 0 {
        return None;
    }
    // In 8.8 fixed point, `p = trunc(256 s + 0.5)` with `s` clamped onto the
    // frame (invalid lanes get coordinate 0): `256 s` is exact (a power of
    // two), so `p = 256 floor(s) + round(256 (s - floor(s)))`, the
    // reference's `x0` and `ax`; a point within the tolerance left of the
    // frame gives 0 (truncation towards 0), one past its right end `256 max`.
    // `x0` is then clamped to `max_x0` as the reference does (`ax = 256` on
    // the last column), so no tap lies past the row.
    let (c256, half) = (_mm256_set1_ps(256.0), _mm256_set1_ps(0.5));
    let fixed = |s: __m256, max: f32, max0: i32| {
        let s = _mm256_and_ps(s, valid);
        let p = _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(s, c256), half));
        let p = _mm256_min_epi32(p, _mm256_set1_epi32((max * 256.0) as i32));
        let p0 = _mm256_min_epi32(_mm256_srai_epi32::<8>(p), _mm256_set1_epi32(max0));
        (p0, _mm256_sub_epi32(p, _mm256_slli_epi32::<8>(p0)))
    };
    let (x0, ax) = fixed(sx, g.max_x, g.max_x0);
    let (y0, ay) = fixed(sy, g.max_y, g.max_y0);
    let i256 = _mm256_set1_epi32(256);
    Some(Taps8 {
        mask,
        x0,
        y0,
        ax,
        ay,
        bx: _mm256_sub_epi32(i256, ax),
        by: _mm256_sub_epi32(i256, ay),
    })
}
