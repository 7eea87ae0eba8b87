//! Pass 2 of an evaluation: bilinear residuals `I(u, v) - T` of a chunk of
//! points, the one pass that gathers from the image. The scalar reference,
//! an AVX2 kernel (hardware gathers) and a WebAssembly `simd128` one (lane
//! loads) with the same arithmetic, bit-exact with it; [`residuals`] picks one.

use crate::image::GrayImage;

/// Bilinear residuals `I(u, v) - T` of points at `(pu, pv)` (NaN outside the
/// image or on invalid pixels) into `pe`, by the fastest kernel this CPU has.
#[inline(always)]
pub(super) fn residuals(img: &GrayImage, pu: &[f32], pv: &[f32], tv: &[f32], pe: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2.
        return with_vector_kernel(img, pu, pv, tv, pe, |pu, pv, tv, pe| unsafe {
            residuals_avx2(img, pu, pv, tv, pe)
        });
    }
    #[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
    // SAFETY: compiled only where the module is built with simd128.
    return with_vector_kernel(img, pu, pv, tv, pe, |pu, pv, tv, pe| unsafe {
        residuals_simd128(img, pu, pv, tv, pe)
    });
    #[allow(unreachable_code)]
    residuals_scalar(img, pu, pv, tv, pe);
}

/// [`residuals`] by a vector kernel: `kernel` takes the points (as many as
/// every slice holds) and returns how many it did, a multiple of its width;
/// the scalar reference does the rest, and all of them when the image's lane
/// offsets do not fit ([`lane_offsets_fit`]).
#[cfg(any(
    target_arch = "x86_64",
    all(target_arch = "wasm32", target_feature = "simd128")
))]
#[inline(always)]
fn with_vector_kernel(
    img: &GrayImage,
    pu: &[f32],
    pv: &[f32],
    tv: &[f32],
    pe: &mut [f32],
    kernel: impl FnOnce(&[f32], &[f32], &[f32], &mut [f32]) -> usize,
) {
    let n = pe.len().min(pu.len()).min(pv.len()).min(tv.len());
    let done = if lane_offsets_fit(img) {
        kernel(&pu[..n], &pv[..n], &tv[..n], &mut pe[..n])
    } else {
        0
    };
    residuals_scalar(
        img,
        &pu[done..n],
        &pv[done..n],
        &tv[done..n],
        &mut pe[done..n],
    );
}

/// Bilinear samples of `img` at `(pu, pv)` into `out`, each point first
/// clamped into the image (past an edge, the edge's value; NaN coordinates
/// give NaN), by [`residuals`]'s kernels with a template of zeros: the same
/// bits on every CPU. The tracker samples its per-level tables of readout
/// fractions this way ([`crate::shutter::RowTime::level_table`]), a chunk of
/// points at a time.
pub(super) fn sample_clamped(img: &GrayImage, pu: &[f32], pv: &[f32], out: &mut [f32]) {
    const BLOCK: usize = 64;
    const ZEROS: [f32; BLOCK] = [0.0; BLOCK];
    // The kernels sample where `0 <= u < W - 1`: the last column and row
    // are reached a hair inside them.
    let umax = (img.width as f32 - 1.0).max(0.0) * (1.0 - f32::EPSILON);
    let vmax = (img.height as f32 - 1.0).max(0.0) * (1.0 - f32::EPSILON);
    let n = out.len().min(pu.len()).min(pv.len());
    let (mut cu, mut cv) = ([0f32; BLOCK], [0f32; BLOCK]);
    for lo in (0..n).step_by(BLOCK) {
        let len = (n - lo).min(BLOCK);
        let (bu, bv) = (&pu[lo..][..len], &pv[lo..][..len]);
        for q in 0..len {
            cu[q] = bu[q].clamp(0.0, umax);
            cv[q] = bv[q].clamp(0.0, vmax);
        }
        residuals(
            img,
            &cu[..len],
            &cv[..len],
            &ZEROS[..len],
            &mut out[lo..][..len],
        );
    }
}

/// The scalar reference of [`residuals`]. A point is sampled where
/// `0 <= u < W - 1` and `0 <= v < H - 1` (so its four taps are in the image;
/// NaN coordinates fail the test).
#[inline(always)]
pub(super) fn residuals_scalar(
    img: &GrayImage,
    pu: &[f32],
    pv: &[f32],
    tv: &[f32],
    pe: &mut [f32],
) {
    let w = img.width;
    let (umax, vmax) = ((w - 1) as f32, (img.height - 1) as f32);
    let data = &img.data[..];
    for k in 0..pe.len() {
        let (u, v) = (pu[k], pv[k]);
        pe[k] = if u >= 0.0 && v >= 0.0 && u < umax && v < vmax {
            let (x0, y0) = (u as usize, v as usize);
            let (ax, ay) = (u - x0 as f32, v - y0 as f32);
            let idx = y0 * w + x0;
            match (data.get(idx..idx + 2), data.get(idx + w..idx + w + 2)) {
                (Some(t), Some(b)) => {
                    let top = t[0] + (t[1] - t[0]) * ax;
                    let bot = b[0] + (b[1] - b[0]) * ax;
                    top + (bot - top) * ay - tv[k]
                }
                _ => f32::NAN,
            }
        } else {
            f32::NAN
        };
    }
}

/// Whether the vector kernels' 32-bit lane offsets reach every tap of an
/// inside point (all below `w h`); an image that fails goes the scalar way.
#[cfg_attr(
    not(any(
        target_arch = "x86_64",
        all(target_arch = "wasm32", target_feature = "simd128")
    )),
    allow(dead_code)
)]
fn lane_offsets_fit(img: &GrayImage) -> bool {
    let (w, h) = (img.width, img.height);
    w >= 2 && h >= 2 && img.data.len() >= w * h && w * h <= i32::MAX as usize
}

/// [`residuals_scalar`] eight points at a time with hardware gathers: the
/// same bounds test (ordered compares, so NaN fails), truncation, taps and
/// operations in the same order (no fused multiply-add), so the same bits.
/// Points outside are given tap index 0 and their result replaced by NaN.
/// Returns how many points it did (a multiple of 8), the rest left to the
/// scalar reference ([`with_vector_kernel`]).
///
/// # Safety
/// The CPU must have AVX2; `pu`, `pv` and `tv` must hold as many points as
/// `pe`, and the image's lane offsets must fit ([`lane_offsets_fit`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn residuals_avx2(
    img: &GrayImage,
    pu: &[f32],
    pv: &[f32],
    tv: &[f32],
    pe: &mut [f32],
) -> usize {
    use std::arch::x86_64::*;
    let (w, h) = (img.width, img.height);
    let n8 = pe.len() / 8 * 8;
    let base = img.data.as_ptr();
    let (umax, vmax) = (
        _mm256_set1_ps((w - 1) as f32),
        _mm256_set1_ps((h - 1) as f32),
    );
    let zero = _mm256_setzero_ps();
    let width = _mm256_set1_epi32(w as i32);
    let nan = _mm256_set1_ps(f32::NAN);
    for i in (0..n8).step_by(8) {
        // SAFETY: `i + 8 <= n` and every slice holds `n`.
        let u = _mm256_loadu_ps(pu.as_ptr().add(i));
        let v = _mm256_loadu_ps(pv.as_ptr().add(i));
        let t = _mm256_loadu_ps(tv.as_ptr().add(i));
        let inside = _mm256_and_ps(
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(u, zero),
                _mm256_cmp_ps::<_CMP_GE_OQ>(v, zero),
            ),
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LT_OQ>(u, umax),
                _mm256_cmp_ps::<_CMP_LT_OQ>(v, vmax),
            ),
        );
        // Inside, `u` and `v` are in `[0, W - 1)` and `[0, H - 1)`, where
        // truncation is the scalar `as usize`; outside, they become 0.
        let (u, v) = (_mm256_and_ps(u, inside), _mm256_and_ps(v, inside));
        let (x0, y0) = (_mm256_cvttps_epi32(u), _mm256_cvttps_epi32(v));
        let ax = _mm256_sub_ps(u, _mm256_cvtepi32_ps(x0));
        let ay = _mm256_sub_ps(v, _mm256_cvtepi32_ps(y0));
        let idx = _mm256_add_epi32(_mm256_mullo_epi32(y0, width), x0);
        // SAFETY: `idx + w + 1 <= (H - 1) W + W - 1 < W H <= data.len()`.
        let t0 = _mm256_i32gather_ps::<4>(base, idx);
        let t1 = _mm256_i32gather_ps::<4>(base.add(1), idx);
        let b0 = _mm256_i32gather_ps::<4>(base.add(w), idx);
        let b1 = _mm256_i32gather_ps::<4>(base.add(w + 1), idx);
        let top = _mm256_add_ps(t0, _mm256_mul_ps(_mm256_sub_ps(t1, t0), ax));
        let bot = _mm256_add_ps(b0, _mm256_mul_ps(_mm256_sub_ps(b1, b0), ax));
        let e = _mm256_sub_ps(
            _mm256_add_ps(top, _mm256_mul_ps(_mm256_sub_ps(bot, top), ay)),
            t,
        );
        _mm256_storeu_ps(pe.as_mut_ptr().add(i), _mm256_blendv_ps(nan, e, inside));
    }
    n8
}

/// [`residuals_scalar`] four points at a time in WebAssembly SIMD, which has
/// no gathers: each point's two pairs of taps (a tap and its right
/// neighbour, 8 bytes) are loaded straight into a 64-bit lane, and the pairs
/// of two points are split into left and right taps by a shuffle. The same
/// bounds test, truncation and operations in the same order (WebAssembly has
/// no fused multiply-add), so the same bits; points outside read the taps at
/// index 0 and their result is replaced by NaN. Returns how many points it
/// did (a multiple of 4), as [`residuals_avx2`].
///
/// # Safety
/// As [`residuals_avx2`]'s slices and image, beyond the module being built
/// with `simd128` (the taps read are those of inside points, checked against
/// the image as the AVX2 kernel does).
#[cfg(all(target_arch = "wasm32", target_feature = "simd128"))]
pub(super) unsafe fn residuals_simd128(
    img: &GrayImage,
    pu: &[f32],
    pv: &[f32],
    tv: &[f32],
    pe: &mut [f32],
) -> usize {
    use std::arch::wasm32::*;
    let (w, h) = (img.width, img.height);
    let n = pe.len();
    // Below 2^23 the offsets are exact in f32 and come out of the float
    // trick (`t + 2^23` has the bits `0x4B00_0000 + t`); else integer lanes.
    let small = w * h < 1 << 23;
    let to_int = |t: v128| {
        i32x4_sub(
            f32x4_add(t, f32x4_splat(8_388_608.0)),
            i32x4_splat(0x4B00_0000),
        )
    };
    let n4 = n / 4 * 4;
    let base = img.data.as_ptr();
    let (umax, vmax) = (f32x4_splat((w - 1) as f32), f32x4_splat((h - 1) as f32));
    let (zero, width_f, width) = (
        f32x4_splat(0.0),
        f32x4_splat(w as f32),
        i32x4_splat(w as i32),
    );
    let nan = f32x4_splat(f32::NAN);
    for i in (0..n4).step_by(4) {
        // SAFETY: `i + 4 <= n` and every slice holds `n`.
        let u = v128_load(pu.as_ptr().add(i) as *const v128);
        let v = v128_load(pv.as_ptr().add(i) as *const v128);
        let t = v128_load(tv.as_ptr().add(i) as *const v128);
        let inside = v128_and(
            v128_and(f32x4_ge(u, zero), f32x4_ge(v, zero)),
            v128_and(f32x4_lt(u, umax), f32x4_lt(v, vmax)),
        );
        // Inside, truncation is the scalar `as usize`; outside, 0.
        let (u, v) = (v128_and(u, inside), v128_and(v, inside));
        let (xf, yf) = (f32x4_trunc(u), f32x4_trunc(v));
        let (ax, ay) = (f32x4_sub(u, xf), f32x4_sub(v, yf));
        let idx = if small {
            to_int(f32x4_add(f32x4_mul(yf, width_f), xf))
        } else {
            i32x4_add(i32x4_mul(to_int(yf), width), to_int(xf))
        };
        // SAFETY: `idx + w + 1 <= (H - 1) W + W - 1 < W H <= data.len()`.
        let at = |k: u32, row: usize| base.add(k as usize + row) as *const u64;
        let pairs = |row: usize| {
            let (i0, i1) = (i32x4_extract_lane::<0>(idx), i32x4_extract_lane::<1>(idx));
            let (i2, i3) = (i32x4_extract_lane::<2>(idx), i32x4_extract_lane::<3>(idx));
            let p01 =
                v128_load64_lane::<1>(v128_load64_zero(at(i0 as u32, row)), at(i1 as u32, row));
            let p23 =
                v128_load64_lane::<1>(v128_load64_zero(at(i2 as u32, row)), at(i3 as u32, row));
            (
                i32x4_shuffle::<0, 2, 4, 6>(p01, p23),
                i32x4_shuffle::<1, 3, 5, 7>(p01, p23),
            )
        };
        let ((t0, t1), (b0, b1)) = (pairs(0), pairs(w));
        let top = f32x4_add(t0, f32x4_mul(f32x4_sub(t1, t0), ax));
        let bot = f32x4_add(b0, f32x4_mul(f32x4_sub(b1, b0), ax));
        let e = f32x4_sub(f32x4_add(top, f32x4_mul(f32x4_sub(bot, top), ay)), t);
        v128_store(
            pe.as_mut_ptr().add(i) as *mut v128,
            v128_bitselect(e, nan, inside),
        );
    }
    n4
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points inside, on and past every edge, NaN and infinite, against the
    /// scalar reference, bit for bit (NaN as NaN).
    #[test]
    fn kernels_match_the_scalar_reference() {
        let (w, h) = (37usize, 23usize);
        let mut img = GrayImage::new(w, h);
        for (i, p) in img.data.iter_mut().enumerate() {
            *p = ((i * 7919) % 1013) as f32 / 1013.0;
        }
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f32 / (1u64 << 53) as f32
        };
        let special = [
            -1.0,
            -1e-7,
            0.0,
            0.5,
            (w - 2) as f32 + 0.999,
            (w - 1) as f32,
            (h - 1) as f32,
            (h - 1) as f32 - 1e-4,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e9,
        ];
        let n = 203;
        let (mut pu, mut pv) = (vec![0f32; n], vec![0f32; n]);
        for k in 0..n {
            pu[k] = if k % 5 == 0 {
                special[k % special.len()]
            } else {
                rnd() * (w as f32 + 4.0) - 2.0
            };
            pv[k] = if k % 7 == 0 {
                special[(k / 7) % special.len()]
            } else {
                rnd() * (h as f32 + 4.0) - 2.0
            };
        }
        let tv: Vec<f32> = (0..n).map(|_| rnd()).collect();
        let mut want = vec![0f32; n];
        residuals_scalar(&img, &pu, &pv, &tv, &mut want);
        assert!(want.iter().any(|e| e.is_nan()) && want.iter().any(|e| e.is_finite()));
        let mut got = vec![1f32; n];
        residuals(&img, &pu, &pv, &tv, &mut got);
        for k in 0..n {
            assert_eq!(
                got[k].to_bits(),
                want[k].to_bits(),
                "point {k} at ({}, {})",
                pu[k],
                pv[k]
            );
        }
    }

    /// The tracker's per-level tables of readout fractions (a distorted
    /// lens), sampled through the kernels, agree with the finest level's
    /// table as [`RowTime::at`] reads it: exactly at level 0 but for the
    /// last column and row, and within a small fraction of a row on the
    /// coarser levels; past the edges they clamp, and NaN stays NaN.
    #[test]
    fn row_time_tables_sample_as_the_lookup() {
        use crate::camera::CameraModel;
        use crate::shutter::RowTime;
        let sensor =
            CameraModel::fisheye_hfov(320, 180, 150.0, [0.05, -0.01, 0.002, -0.0005]).unwrap();
        let image = CameraModel::pinhole_hfov(320, 180, 110.0).unwrap();
        let rows = RowTime::new(&sensor, &image);
        assert!(matches!(rows, RowTime::Table { .. }));
        let (mut w, mut h) = (320usize, 180usize);
        for level in 0..4 {
            let table = rows.level_table(level, w, h).expect("a table");
            let mut pu: Vec<f32> = Vec::new();
            let mut pv: Vec<f32> = Vec::new();
            for i in 0..997 {
                pu.push(((i * 7919) % 1009) as f32 / 1009.0 * (w as f32 + 6.0) - 3.0);
                pv.push(((i * 104_729) % 1013) as f32 / 1013.0 * (h as f32 + 6.0) - 3.0);
            }
            pu.extend([f32::NAN, 0.0, (w - 1) as f32, -1e9, f32::INFINITY]);
            pv.extend([1.0, f32::NAN, (h - 1) as f32, 1e9, 2.0]);
            let mut got = vec![0f32; pu.len()];
            sample_clamped(&table, &pu, &pv, &mut got);
            // The level's own grid against the finest one's: inside the
            // level's image, bilinear between the same values on a coarser
            // grid (the bound, `s` on a level-`l` grid with `2^l` times the
            // spacing, is a sixth of a finest row at level 3 and shrinks
            // fourfold per level). Past its edges, where no point is sampled
            // but a landing's iterates may stray, the level clamps at its
            // own last pixel, not at the finest level's.
            let (mut inner, mut edge) = (0f32, 0f32);
            for k in 0..pu.len() {
                let want = rows.at(level, pu[k], pv[k]);
                if pu[k].is_nan() || pv[k].is_nan() {
                    assert!(got[k].is_nan(), "level {level}: NaN point gave {}", got[k]);
                    continue;
                }
                assert!(
                    want.is_finite() && got[k].is_finite(),
                    "level {level} point {k}"
                );
                let inside = (0.0..=(w - 1) as f32).contains(&pu[k])
                    && (0.0..=(h - 1) as f32).contains(&pv[k]);
                let worst = if inside { &mut inner } else { &mut edge };
                *worst = worst.max((got[k] - want).abs());
            }
            eprintln!("level {level}: inside {inner:e}, edges {edge:e}");
            let bound = 1e-6 + 1e-5 * (4f32.powi(level as i32) - 1.0);
            assert!(
                inner <= bound,
                "level {level}: inside, off by {inner} > {bound}"
            );
            let rows_apart = (1 << level) as f32 / 180.0;
            assert!(
                edge <= rows_apart,
                "level {level}: past the edges, off by {edge}"
            );
            (w, h) = (w / 2, h / 2);
        }
        // An affine readout has no table.
        let pinhole = CameraModel::pinhole_hfov(320, 180, 90.0).unwrap();
        assert!(RowTime::new(&pinhole, &pinhole)
            .level_table(0, 320, 180)
            .is_none());
    }
}
