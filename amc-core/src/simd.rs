//! Vectorized bilinear sampling (x86-64 AVX2), used when the CPU has it.
//!
//! Eight output pixels at a time: coordinates, weights and byte offsets are
//! computed in 32-bit lanes, the four bilinear taps are fetched with masked
//! 32-bit gathers (one dword holds a pixel's R, G, B), and the 8.8 fixed-point
//! interpolation is done per channel in integer lanes, bit-exact with the
//! scalar path in `render.rs`. Lanes whose coordinate falls outside the frame
//! are masked off and contribute nothing.

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::*;

/// Bytes a frame buffer must have past its last pixel for the gathers: the
/// last tap reads a whole dword starting at the last pixel (3 bytes for RGB).
pub const FRAME_PADDING: usize = 4;

/// Whether the AVX2 kernel can run on this CPU.
pub fn avx2_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Frame geometry for the kernel.
#[derive(Clone, Copy, Debug)]
pub struct KernelGeometry {
    pub channels: i32,
    pub stride: i32,
    pub max_x0: i32,
    pub max_y0: i32,
    pub max_x: f32,
    pub max_y: f32,
}

/// Accumulates the samples of one frame along one output row:
/// for `u in 0..n8` (a multiple of 8), `acc_{r,g,b}[u] += sample`, `count[u] += 1`
/// where `(xs[u], ys[u])` lies inside the frame.
///
/// # Safety
/// The CPU must support AVX2 ([`avx2_available`]); `data` must hold the whole
/// frame plus [`FRAME_PADDING`] bytes; all slices must have at least `n8` elements.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[allow(clippy::too_many_arguments)]
pub unsafe fn accumulate_row_avx2(
    data: &[u8],
    g: KernelGeometry,
    xs: &[f32],
    ys: &[f32],
    n8: usize,
    acc_r: &mut [u32],
    acc_g: &mut [u32],
    acc_b: &mut [u32],
    count: &mut [u32],
) {
    debug_assert!(n8 % 8 == 0 && xs.len() >= n8 && ys.len() >= n8);
    debug_assert!(acc_r.len() >= n8 && acc_g.len() >= n8 && acc_b.len() >= n8 && count.len() >= n8);
    let base = data.as_ptr() as *const i32;
    let zero_ps = _mm256_setzero_ps();
    let max_x = _mm256_set1_ps(g.max_x);
    let max_y = _mm256_set1_ps(g.max_y);
    let max_x0 = _mm256_set1_epi32(g.max_x0);
    let max_y0 = _mm256_set1_epi32(g.max_y0);
    let stride = _mm256_set1_epi32(g.stride);
    let chans = _mm256_set1_epi32(g.channels);
    let c256 = _mm256_set1_ps(256.0);
    let half = _mm256_set1_ps(0.5);
    let i256 = _mm256_set1_epi32(256);
    let i128 = _mm256_set1_epi32(128);
    let byte = _mm256_set1_epi32(0xFF);
    let one = _mm256_set1_epi32(1);
    let mut u = 0;
    while u < n8 {
        let sx = _mm256_loadu_ps(xs.as_ptr().add(u));
        let sy = _mm256_loadu_ps(ys.as_ptr().add(u));
        // NaN compares false: NaN coordinates are invalid.
        let valid = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps(sx, zero_ps, _CMP_GE_OQ),
                _mm256_cmp_ps(sy, zero_ps, _CMP_GE_OQ),
            ),
            _mm256_and_ps(
                _mm256_cmp_ps(sx, max_x, _CMP_LE_OQ),
                _mm256_cmp_ps(sy, max_y, _CMP_LE_OQ),
            ),
        );
        let mask = _mm256_castps_si256(valid);
        if _mm256_testz_si256(mask, mask) != 0 {
            u += 8;
            continue;
        }
        // Invalid lanes get coordinate 0 so the integer conversions stay tame.
        let sxv = _mm256_and_ps(sx, valid);
        let syv = _mm256_and_ps(sy, valid);
        let x0 = _mm256_min_epi32(_mm256_cvttps_epi32(sxv), max_x0);
        let y0 = _mm256_min_epi32(_mm256_cvttps_epi32(syv), max_y0);
        let fx = _mm256_sub_ps(sxv, _mm256_cvtepi32_ps(x0));
        let fy = _mm256_sub_ps(syv, _mm256_cvtepi32_ps(y0));
        let ax = _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(fx, c256), half));
        let ay = _mm256_cvttps_epi32(_mm256_add_ps(_mm256_mul_ps(fy, c256), half));
        let bx = _mm256_sub_epi32(i256, ax);
        let by = _mm256_sub_epi32(i256, ay);
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
        macro_rules! channel {
            ($shift:expr) => {{
                let c00 = _mm256_and_si256(_mm256_srli_epi32::<$shift>(p00), byte);
                let c01 = _mm256_and_si256(_mm256_srli_epi32::<$shift>(p01), byte);
                let c10 = _mm256_and_si256(_mm256_srli_epi32::<$shift>(p10), byte);
                let c11 = _mm256_and_si256(_mm256_srli_epi32::<$shift>(p11), byte);
                let top =
                    _mm256_add_epi32(_mm256_mullo_epi32(c00, bx), _mm256_mullo_epi32(c01, ax));
                let bot =
                    _mm256_add_epi32(_mm256_mullo_epi32(c10, bx), _mm256_mullo_epi32(c11, ax));
                let v = _mm256_add_epi32(
                    _mm256_add_epi32(_mm256_mullo_epi32(top, by), _mm256_mullo_epi32(bot, ay)),
                    i128,
                );
                _mm256_and_si256(_mm256_srli_epi32::<8>(v), mask)
            }};
        }
        let r = channel!(0);
        let gg = channel!(8);
        let b = channel!(16);
        let add = |acc: &mut [u32], v: __m256i| {
            let p = acc.as_mut_ptr().add(u) as *mut __m256i;
            _mm256_storeu_si256(p, _mm256_add_epi32(_mm256_loadu_si256(p), v));
        };
        add(acc_r, r);
        add(acc_g, gg);
        add(acc_b, b);
        add(count, _mm256_and_si256(mask, one));
        u += 8;
    }
}
