//! Direct (intensity-based) homography fit between two grayscale frames over
//! their valid pixels, for the Liu et al. metrics.
//!
//! Coordinates are *normalized* per frame, so frames of different sizes (our
//! cropped outputs, the full-size input) compare in units of their own width:
//! ```text
//! x_n = (x - (W - 1) / 2) / W,   y_n = (y - (H - 1) / 2) / W
//! ```
//! [`fit`] finds the homography `G` (with `g33 = 1`) that maps `dst` into
//! `src`, i.e. `dst(p) ~ src(G p)`, minimizing
//! ```text
//! sum over p valid in dst with G p valid in src of  huber(src(G p) - dst(p))
//! ```
//! by Levenberg-Marquardt on the eight entries of `G` (forward additive
//! Lucas-Kanade), coarse to fine over a box pyramid (finest level at most
//! [`FINEST_WIDTH`] px wide), after an exhaustive translation search at the
//! coarsest level around the initial guess. Invalid pixels are `NaN`; a box
//! average with any invalid pixel is invalid, so borders never leak in.

use amc_core::image::GrayImage;
use nalgebra::{Matrix3, SMatrix, SVector};

/// Width (px) of the finest pyramid level the fit works on.
pub const FINEST_WIDTH: usize = 160;
/// Width (px) under which no coarser level is built.
const COARSEST_WIDTH: usize = 40;
/// Huber threshold on the luma residual (intensities in `[0, 1]`).
const HUBER: f64 = 0.04;
/// Translation search at the coarsest level: +- this many pixels.
const SEARCH_PX: i32 = 6;
/// Parameter step (normalized units, ~1/100 px at the finest level) that ends the iterations.
const CONVERGED: f64 = 5e-5;
/// Levels with more pixels are sampled on every other row and column.
const SUBSAMPLE_ABOVE: usize = 8000;
/// Fewest usable pixels for a fit.
const MIN_PIXELS: usize = 200;

/// Result of one fit.
#[derive(Clone, Copy, Debug)]
pub struct Fit {
    /// Homography from `dst` normalized coordinates into `src` normalized coordinates.
    pub h: Matrix3<f64>,
    /// RMS luma residual over the pixels used at the finest level.
    pub rms_residual: f64,
}

/// A frame prepared for fitting: a pyramid of valid-masked luma (`NaN` = invalid).
#[derive(Clone, Debug)]
pub struct Pyramid {
    /// Width of the frame the pyramid was built from (defines normalized coordinates).
    full_width: usize,
    full_height: usize,
    /// Finest first.
    levels: Vec<GrayImage>,
    /// Full-resolution pixels per level pixel (a power of two), per level.
    scales: Vec<f64>,
}

/// One pyramid step: the core's 2x2 box average (the tracker's own pyramid step).
fn half(src: &GrayImage) -> GrayImage {
    let mut out = GrayImage::default();
    amc_core::pyramid::half_into(src, &mut out);
    out
}

/// Area-averages `src` along x by the factor `f >= 1` into `w` columns (column
/// `x` covers source columns `[x f, (x + 1) f)`): each output pixel is the
/// coverage-weighted mean of the source pixels under it; `NaN` if any is `NaN`.
fn shrink_x(src: &GrayImage, w: usize, f: f64) -> GrayImage {
    let mut out = GrayImage::new(w, src.height);
    for x in 0..w {
        let (a, b) = (x as f64 * f, (x + 1) as f64 * f);
        let (i0, i1) = (a.floor() as usize, (b.ceil() as usize).min(src.width));
        for y in 0..src.height {
            let row = &src.data[y * src.width..(y + 1) * src.width];
            let (mut sum, mut wsum) = (0f64, 0f64);
            for (i, &v) in row.iter().enumerate().take(i1).skip(i0) {
                let wt = (b.min(i as f64 + 1.0) - a.max(i as f64)).max(0.0);
                if wt > 0.0 {
                    sum += wt * v as f64;
                    wsum += wt;
                }
            }
            out.data[y * w + x] = (sum / wsum.max(1e-12)) as f32;
        }
    }
    out
}

/// Transpose of a gray image.
fn transpose(src: &GrayImage) -> GrayImage {
    let mut out = GrayImage::new(src.height, src.width);
    for y in 0..src.height {
        for x in 0..src.width {
            out.data[x * src.height + y] = src.data[y * src.width + x];
        }
    }
    out
}

impl Pyramid {
    /// Builds the pyramid of `gray` (`NaN` where invalid), halving until the
    /// finest level is at most [`FINEST_WIDTH`] wide.
    pub fn new(gray: &GrayImage) -> Self {
        let mut cur = gray.clone();
        let mut scale = 1.0;
        while cur.width > FINEST_WIDTH && cur.width / 2 >= COARSEST_WIDTH && cur.height >= 8 {
            cur = half(&cur);
            scale *= 2.0;
        }
        Self::from_finest(gray, cur, scale)
    }

    /// Builds the pyramid of `gray` with its finest level area-resampled to
    /// `width` (at most `gray.width`), so that two frames showing the scene at
    /// different pixel scales can be compared at the same sampling density.
    pub fn with_finest_width(gray: &GrayImage, width: usize) -> Self {
        let w = width.clamp(COARSEST_WIDTH.min(gray.width), gray.width);
        if w == gray.width {
            return Self::from_finest(gray, gray.clone(), 1.0);
        }
        let f = gray.width as f64 / w as f64;
        let h = ((gray.height as f64 / f).floor() as usize).clamp(1, gray.height);
        let finest = transpose(&shrink_x(&transpose(&shrink_x(gray, w, f)), h, f));
        Self::from_finest(gray, finest, f)
    }

    fn from_finest(gray: &GrayImage, finest: GrayImage, scale: f64) -> Self {
        let mut levels = vec![finest];
        let mut scales = vec![scale];
        let mut scale = scale;
        while let Some(last) = levels.last() {
            if last.width / 2 < COARSEST_WIDTH || last.height / 2 < 4 {
                break;
            }
            let next = half(last);
            levels.push(next);
            scale *= 2.0;
            scales.push(scale);
        }
        Self {
            full_width: gray.width,
            full_height: gray.height,
            levels,
            scales,
        }
    }

    /// Width of the finest level.
    pub fn finest_width(&self) -> usize {
        self.levels[0].width
    }

    /// Pixel -> normalized coordinates at `level` (an affine map `x_n = a x + b`).
    fn to_norm(&self, level: usize) -> (f64, f64, f64) {
        // Level pixel x covers full-res pixels [x s, (x + 1) s): centre x s + (s - 1) / 2.
        let s = self.scales[level];
        let w = self.full_width as f64;
        let cx = (self.full_width as f64 - 1.0) / 2.0;
        let cy = (self.full_height as f64 - 1.0) / 2.0;
        // x_n = (x s + (s - 1) / 2 - c) / W
        (
            s / w,
            ((s - 1.0) / 2.0 - cx) / w,
            ((s - 1.0) / 2.0 - cy) / w,
        )
    }
}

/// Bilinear sample with gradient; `None` unless all four neighbours are valid.
#[inline]
fn sample_grad(img: &GrayImage, x: f64, y: f64) -> Option<(f64, f64, f64)> {
    if !(x >= 0.0 && y >= 0.0) {
        return None;
    }
    // Non-negative here, so truncation is floor (and much cheaper than libm's floor).
    let (x0, y0) = (x as usize, y as usize);
    if x0 + 1 >= img.width || y0 + 1 >= img.height {
        return None;
    }
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let i = y0 * img.width + x0;
    let a = img.data[i] as f64;
    let b = img.data[i + 1] as f64;
    let c = img.data[i + img.width] as f64;
    let d = img.data[i + img.width + 1] as f64;
    let v = a * (1.0 - fx) * (1.0 - fy) + b * fx * (1.0 - fy) + c * (1.0 - fx) * fy + d * fx * fy;
    if !v.is_finite() {
        return None;
    }
    let gx = (b - a) * (1.0 - fy) + (d - c) * fy;
    let gy = (c - a) * (1.0 - fx) + (d - b) * fx;
    Some((v, gx, gy))
}

/// Applies `h` to `(x, y)`.
#[inline]
pub fn apply(h: &Matrix3<f64>, x: f64, y: f64) -> Option<(f64, f64)> {
    let d = h[(2, 0)] * x + h[(2, 1)] * y + h[(2, 2)];
    if d.abs() < 1e-9 {
        return None;
    }
    Some((
        (h[(0, 0)] * x + h[(0, 1)] * y + h[(0, 2)]) / d,
        (h[(1, 0)] * x + h[(1, 1)] * y + h[(1, 2)]) / d,
    ))
}

/// Sum of squared residuals, count, and (optionally) the normal equations
/// (`jtj` holds the upper triangle, row-major, until [`Accum::normal_matrix`]).
struct Accum {
    jtj: [f64; 36],
    jtr: SVector<f64, 8>,
    cost: f64,
    sq: f64,
    n: usize,
}

fn accumulate(
    src: &Pyramid,
    dst: &Pyramid,
    level: usize,
    h: &Matrix3<f64>,
    with_jacobian: bool,
) -> Accum {
    let (s_img, d_img) = (&src.levels[level], &dst.levels[level]);
    let (sa, sbx, sby) = src.to_norm(level);
    let (da, dbx, dby) = dst.to_norm(level);
    // Every pixel of small levels, every other row and column of large ones.
    let step = if d_img.width * d_img.height > SUBSAMPLE_ABOVE {
        2
    } else {
        1
    };
    let mut acc = Accum {
        jtj: [0.0; 36],
        jtr: SVector::zeros(),
        cost: 0.0,
        sq: 0.0,
        n: 0,
    };
    for v in (0..d_img.height).step_by(step) {
        for u in (0..d_img.width).step_by(step) {
            let t = d_img.data[v * d_img.width + u] as f64;
            if !t.is_finite() {
                continue;
            }
            let (x, y) = (da * u as f64 + dbx, da * v as f64 + dby);
            let Some((xn, yn)) = apply(h, x, y) else {
                continue;
            };
            // Normalized -> source level pixels.
            let (px, py) = ((xn - sbx) / sa, (yn - sby) / sa);
            let Some((val, gx, gy)) = sample_grad(s_img, px, py) else {
                continue;
            };
            let r = val - t;
            let ar = r.abs();
            let (wgt, cost) = if ar <= HUBER {
                (1.0, 0.5 * r * r)
            } else {
                (HUBER / ar, HUBER * (ar - 0.5 * HUBER))
            };
            acc.cost += cost;
            acc.sq += r * r;
            acc.n += 1;
            if with_jacobian {
                // d(src)/d(normalized) = gradient per level pixel / sa.
                let (gxn, gyn) = (gx / sa, gy / sa);
                let d = h[(2, 0)] * x + h[(2, 1)] * y + 1.0;
                let j = [
                    gxn * x / d,
                    gxn * y / d,
                    gxn / d,
                    gyn * x / d,
                    gyn * y / d,
                    gyn / d,
                    -(gxn * xn + gyn * yn) * x / d,
                    -(gxn * xn + gyn * yn) * y / d,
                ];
                let mut k = 0;
                for a in 0..8 {
                    let wa = wgt * j[a];
                    for &jb in &j[a..] {
                        acc.jtj[k] += wa * jb;
                        k += 1;
                    }
                    acc.jtr[a] += wa * r;
                }
            }
        }
    }
    acc
}

impl Accum {
    /// The full symmetric `J^T W J`.
    fn normal_matrix(&self) -> SMatrix<f64, 8, 8> {
        let mut m = SMatrix::<f64, 8, 8>::zeros();
        let mut k = 0;
        for a in 0..8 {
            for b in a..8 {
                m[(a, b)] = self.jtj[k];
                m[(b, a)] = self.jtj[k];
                k += 1;
            }
        }
        m
    }
}

fn with_params(h: &Matrix3<f64>, delta: &SVector<f64, 8>) -> Matrix3<f64> {
    let mut out = *h;
    for k in 0..8 {
        out[(k / 3, k % 3)] += delta[k];
    }
    out
}

/// Levenberg-Marquardt at one level; returns the refined homography.
fn refine(
    src: &Pyramid,
    dst: &Pyramid,
    level: usize,
    mut h: Matrix3<f64>,
    iters: usize,
) -> Matrix3<f64> {
    let mut lambda = 1e-3;
    for _ in 0..iters {
        let acc = accumulate(src, dst, level, &h, true);
        if acc.n < MIN_PIXELS / 4 {
            break;
        }
        let jtj = acc.normal_matrix();
        let mut improved = false;
        for _ in 0..6 {
            let mut a = jtj;
            for k in 0..8 {
                a[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let Some(delta) = a.cholesky().map(|c| c.solve(&(-acc.jtr))) else {
                lambda *= 10.0;
                continue;
            };
            let cand = with_params(&h, &delta);
            let new = accumulate(src, dst, level, &cand, false);
            // Compare mean costs: the overlap may change slightly.
            if new.n >= MIN_PIXELS / 4 && new.cost / new.n as f64 <= acc.cost / acc.n as f64 {
                h = cand;
                lambda = (lambda * 0.3).max(1e-7);
                improved = true;
                if delta.norm() < CONVERGED {
                    return h;
                }
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    h
}

/// Fits `G` with `dst(p) ~ src(G p)` (normalized coordinates), starting from `init`.
/// `None` when too few valid pixels overlap.
pub fn fit(src: &Pyramid, dst: &Pyramid, init: &Matrix3<f64>) -> Option<Fit> {
    let top = src.levels.len().min(dst.levels.len()).checked_sub(1)?;
    let mut h = init / init[(2, 2)];
    // Exhaustive translation search at the coarsest level, in its pixel steps.
    let step = src.to_norm(top).0;
    let mut best = (f64::INFINITY, h);
    for dy in -SEARCH_PX..=SEARCH_PX {
        for dx in -SEARCH_PX..=SEARCH_PX {
            let t = Matrix3::new(
                1.0,
                0.0,
                dx as f64 * step,
                0.0,
                1.0,
                dy as f64 * step,
                0.0,
                0.0,
                1.0,
            );
            let cand = t * h;
            let acc = accumulate(src, dst, top, &cand, false);
            if acc.n < MIN_PIXELS / 8 {
                continue;
            }
            let mean = acc.cost / acc.n as f64;
            if mean < best.0 {
                best = (mean, cand);
            }
        }
    }
    if best.0.is_finite() {
        h = best.1;
    }
    for level in (0..=top).rev() {
        h = refine(src, dst, level, h, if level == top { 20 } else { 8 });
        h /= h[(2, 2)];
    }
    let acc = accumulate(src, dst, 0, &h, false);
    if acc.n < MIN_PIXELS {
        return None;
    }
    Some(Fit {
        h,
        rms_residual: (acc.sq / acc.n as f64).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth, textured test image (sum of sines), sampled at normalized coordinates.
    fn texture(xn: f64, yn: f64) -> f32 {
        (0.5 + 0.2 * (17.0 * xn + 3.0 * yn).sin()
            + 0.15 * (23.0 * yn - 5.0 * xn).cos()
            + 0.1 * (41.0 * (xn + yn)).sin()) as f32
    }

    /// Renders `dst(p) = texture(G p)` at `w x h`, NaN where `valid` says no.
    fn render(w: usize, h: usize, g: &Matrix3<f64>) -> GrayImage {
        let mut img = GrayImage::new(w, h);
        let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
        for y in 0..h {
            for x in 0..w {
                let (xn, yn) = ((x as f64 - cx) / w as f64, (y as f64 - cy) / w as f64);
                let (sx, sy) = apply(g, xn, yn).unwrap();
                img.data[y * w + x] = texture(sx, sy);
            }
        }
        img
    }

    fn close(a: &Matrix3<f64>, b: &Matrix3<f64>, tol: f64) -> bool {
        (a - b).abs().max() < tol
    }

    #[test]
    fn recovers_shift_zoom_and_rotation() {
        let src = Pyramid::new(&render(320, 180, &Matrix3::identity()));
        let (c, s) = (0.05f64.cos(), 0.05f64.sin());
        let g = Matrix3::new(
            0.8 * c,
            -0.8 * s,
            0.03,
            0.8 * s,
            0.8 * c,
            -0.02,
            0.0,
            0.0,
            1.0,
        );
        let dst = Pyramid::new(&render(240, 135, &g));
        let f = fit(
            &src,
            &dst,
            &Matrix3::new(0.8, 0.0, 0.0, 0.0, 0.8, 0.0, 0.0, 0.0, 1.0),
        )
        .unwrap();
        assert!(close(&f.h, &g, 2e-3), "{}", f.h);
        assert!(f.rms_residual < 0.01, "{}", f.rms_residual);
    }

    #[test]
    fn ignores_invalid_pixels() {
        let src = Pyramid::new(&render(200, 150, &Matrix3::identity()));
        let g = Matrix3::new(1.0, 0.0, 0.04, 0.0, 1.0, 0.01, 0.0, 0.0, 1.0);
        let mut d = render(200, 150, &g);
        // A black border that is marked invalid must not matter.
        for y in 0..150 {
            for x in 0..30 {
                d.data[y * 200 + x] = f32::NAN;
            }
        }
        let f = fit(&src, &Pyramid::new(&d), &Matrix3::identity()).unwrap();
        assert!(close(&f.h, &g, 1e-3), "{}", f.h);
    }

    #[test]
    fn density_matched_pyramid_fits_the_same() {
        // A 0.75 crop at the input's pixel scale, fitted at matched sampling density.
        let src = Pyramid::new(&render(192, 108, &Matrix3::identity()));
        let g = Matrix3::new(0.75, 0.0, 0.0, 0.0, 0.75, 0.0, 0.0, 0.0, 1.0);
        let out = render(144, 81, &g);
        let dst = Pyramid::with_finest_width(&out, (src.finest_width() as f64 * 0.75) as usize);
        assert_eq!(dst.finest_width(), 72);
        let f = fit(&src, &dst, &g).unwrap();
        assert!(close(&f.h, &g, 1e-3), "{}", f.h);
    }

    #[test]
    fn nothing_valid_is_none() {
        let mut d = GrayImage::new(100, 80);
        d.data.iter_mut().for_each(|v| *v = f32::NAN);
        let src = Pyramid::new(&render(100, 80, &Matrix3::identity()));
        assert!(fit(&src, &Pyramid::new(&d), &Matrix3::identity()).is_none());
    }
}
