//! The literature's stabilization metrics (Liu et al. 2013, "Bundled camera
//! paths for video stabilization"), from homographies in normalized
//! coordinates (see [`super::homography`]).
//!
//! With `A_j` the homography from input frame `j` to output frame `j`
//! (normalized so `a33 = 1`) and `M_j` the one from output `j-1` to output `j`:
//! ```text
//! cropping     c_j = 1 / sqrt|det A_j[0..2, 0..2]|   (kept linear fraction of the input)
//!              clip: mean over frames
//! distortion   d_j = |l_min| / |l_max| of the eigenvalues of A_j[0..2, 0..2]
//!              clip: the worst (smallest) frame
//! stability    P_j = M_j P_{j-1} (P_0 = I); translation path t_j = |(P_j[0,2], P_j[1,2])|,
//!              rotation path r_j = atan2(P_j[1,0], P_j[0,0]);
//!              E_k = |DFT_k(path)|^2 for k = 1 .. N/2 (DC left out);
//!              share = sum_{k=1..5} E_k / sum_k E_k  (Liu's "2nd to 6th" bins);
//!              score = min(share_translation, share_rotation)
//! fixed band   the same share over bins with 0 < f_k <= STABILITY_BAND_HZ, f_k = k fps / N,
//!              independent of the clip's length
//! ITF          mean over consecutive output pairs of PSNR = 10 log10(1 / MSE) on luma in [0, 1],
//!              over pixels valid in both
//! ```
//! Higher is better for all four (1 is ideal for cropping, distortion and stability).

use nalgebra::Matrix3;

/// Upper edge (Hz) of the fixed low-frequency band of the stability score.
pub const STABILITY_BAND_HZ: f64 = 1.0;
/// Bins Liu et al. count as low frequency (after the DC bin): the 2nd to 6th.
pub const LIU_LOW_BINS: usize = 5;

/// The upper-left 2x2 block of `h / h33`.
fn linear_part(h: &Matrix3<f64>) -> [[f64; 2]; 2] {
    let s = h[(2, 2)];
    [
        [h[(0, 0)] / s, h[(0, 1)] / s],
        [h[(1, 0)] / s, h[(1, 1)] / s],
    ]
}

/// Kept linear fraction of the input, `1 / sqrt|det A|` of the 2x2 part of `a` (input to output).
pub fn cropping_ratio(a: &Matrix3<f64>) -> f64 {
    let m = linear_part(a);
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    1.0 / det.abs().sqrt()
}

/// Ratio of the smaller to the larger eigenvalue magnitude of the 2x2 part of `a`
/// (1 = no anisotropic stretch; a rotation and uniform scale give 1).
pub fn distortion_value(a: &Matrix3<f64>) -> f64 {
    let m = linear_part(a);
    let tr = m[0][0] + m[1][1];
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    let disc = tr * tr - 4.0 * det;
    if disc < 0.0 {
        // A complex pair: equal magnitudes.
        return 1.0;
    }
    let r = disc.sqrt();
    let (l1, l2) = (((tr + r) / 2.0).abs(), ((tr - r) / 2.0).abs());
    let (lo, hi) = (l1.min(l2), l1.max(l2));
    if hi > 0.0 {
        lo / hi
    } else {
        0.0
    }
}

/// Energy `|DFT_k|^2` of `path` for `k = 1 ..= N/2`.
fn spectrum(path: &[f64]) -> Vec<f64> {
    let n = path.len();
    (1..=n / 2)
        .map(|k| {
            let (mut re, mut im) = (0.0, 0.0);
            for (i, &x) in path.iter().enumerate() {
                let ph = -2.0 * std::f64::consts::PI * (k * i) as f64 / n as f64;
                re += x * ph.cos();
                im += x * ph.sin();
            }
            re * re + im * im
        })
        .collect()
}

/// Share of the energy of `path` in the first `bins` non-DC bins (`None` for too short paths
/// or a constant path).
pub fn low_frequency_share(path: &[f64], bins: usize) -> Option<f64> {
    let e = spectrum(path);
    let total: f64 = e.iter().sum();
    if e.len() < bins || total <= 0.0 || !total.is_finite() {
        return None;
    }
    Some(e[..bins].iter().sum::<f64>() / total)
}

/// Share of the energy of `path` (sampled at `fps`) at `0 < f <= band_hz`.
pub fn band_share(path: &[f64], fps: f64, band_hz: f64) -> Option<f64> {
    let n = path.len();
    if n < 2 || fps <= 0.0 {
        return None;
    }
    let bins = (band_hz * n as f64 / fps).floor() as usize;
    if bins == 0 {
        return None;
    }
    low_frequency_share(path, bins.min(n / 2))
}

/// Stability scores of a clip.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Stability {
    /// Liu et al.: min over translation and rotation of the 2nd-6th bin share.
    pub score: Option<f64>,
    pub translation: Option<f64>,
    pub rotation: Option<f64>,
    /// The same with the fixed band `0 < f <= STABILITY_BAND_HZ`.
    pub band_score: Option<f64>,
}

fn min_opt(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.min(y)),
        (x, None) => x,
        (None, y) => y,
    }
}

/// Stability from the homographies `M_j` between consecutive outputs (frame `j-1` to `j`).
pub fn stability(consecutive: &[Matrix3<f64>], fps: f64) -> Stability {
    let mut p = Matrix3::identity();
    let (mut t, mut r) = (Vec::new(), Vec::new());
    for m in consecutive {
        p = m * p;
        p /= p[(2, 2)];
        t.push(p[(0, 2)].hypot(p[(1, 2)]));
        r.push(p[(1, 0)].atan2(p[(0, 0)]));
    }
    let translation = low_frequency_share(&t, LIU_LOW_BINS);
    let rotation = low_frequency_share(&r, LIU_LOW_BINS);
    let band = min_opt(
        band_share(&t, fps, STABILITY_BAND_HZ),
        band_share(&r, fps, STABILITY_BAND_HZ),
    );
    Stability {
        score: min_opt(translation, rotation),
        translation,
        rotation,
        band_score: band,
    }
}

/// PSNR (dB) of two luma images in `[0, 1]` over pixels finite in both (`None` if none;
/// identical images give `f64::INFINITY`).
pub fn psnr(a: &[f32], b: &[f32]) -> Option<f64> {
    let (mut sum, mut n) = (0f64, 0u64);
    for (&x, &y) in a.iter().zip(b) {
        let d = (x - y) as f64;
        if d.is_finite() {
            sum += d * d;
            n += 1;
        }
    }
    if n == 0 {
        return None;
    }
    let mse = sum / n as f64;
    Some(if mse > 0.0 {
        10.0 * (1.0 / mse).log10()
    } else {
        f64::INFINITY
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn identity_has_cropping_one_and_distortion_one() {
        let i = Matrix3::identity();
        assert_relative_eq!(cropping_ratio(&i), 1.0);
        assert_relative_eq!(distortion_value(&i), 1.0);
    }

    #[test]
    fn known_zoom_has_known_cropping() {
        // Output = input zoomed 1.25x about the centre (plus a shift): 80% kept.
        let a = Matrix3::new(1.25, 0.0, 0.03, 0.0, 1.25, -0.01, 0.0, 0.0, 1.0);
        assert_relative_eq!(cropping_ratio(&a), 0.8, epsilon = 1e-12);
        assert_relative_eq!(distortion_value(&a), 1.0, epsilon = 1e-12);
        // Scale of the whole matrix does not matter.
        assert_relative_eq!(cropping_ratio(&(a * 3.0)), 0.8, epsilon = 1e-12);
    }

    #[test]
    fn rotation_is_not_distortion_but_stretch_is() {
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        let rot = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
        assert_relative_eq!(distortion_value(&rot), 1.0);
        assert_relative_eq!(cropping_ratio(&rot), 1.0, epsilon = 1e-12);
        let stretch = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0);
        assert_relative_eq!(distortion_value(&stretch), 0.5);
    }

    #[test]
    fn slow_path_is_stable_and_jitter_is_not() {
        let fps = 30.0;
        let n = 300;
        // A smooth sway (one slow sine period, periodic so no spectral leakage)
        // versus 10 Hz jitter.
        let slow: Vec<Matrix3<f64>> = (0..n)
            .map(|j| {
                let dx = 0.001 * (2.0 * std::f64::consts::PI * j as f64 / n as f64).cos();
                Matrix3::new(1.0, 0.0, dx, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
            })
            .collect();
        let s = stability(&slow, fps);
        assert!(s.translation.unwrap() > 0.9, "{s:?}");
        assert!(s.band_score.unwrap() > 0.9, "{s:?}");
        let jitter: Vec<Matrix3<f64>> = (0..n)
            .map(|j| {
                let ph = 2.0 * std::f64::consts::PI * 10.0 * j as f64 / fps;
                let dx = 0.02 * ph.cos();
                let th = 0.01 * ph.sin();
                let (c, s) = (th.cos(), th.sin());
                Matrix3::new(c, -s, dx, s, c, 0.0, 0.0, 0.0, 1.0)
            })
            .collect();
        let j = stability(&jitter, fps);
        assert!(j.score.unwrap() < 0.2, "{j:?}");
        assert!(j.band_score.unwrap() < 0.2, "{j:?}");
    }

    #[test]
    fn band_share_counts_only_bins_in_band() {
        // A pure 0.5 Hz sine over 10 s at 30 fps: all energy in bin 5 (0.5 Hz).
        let p: Vec<f64> = (0..300)
            .map(|i| (2.0 * std::f64::consts::PI * 0.5 * i as f64 / 30.0).sin())
            .collect();
        assert_relative_eq!(band_share(&p, 30.0, 1.0).unwrap(), 1.0, epsilon = 1e-9);
        assert!(band_share(&p, 30.0, 0.4).unwrap() < 1e-9);
        assert!(band_share(&p[..10], 30.0, 1.0).is_none());
    }

    #[test]
    fn psnr_of_known_difference() {
        let a = vec![0.5f32; 100];
        let b = vec![0.6f32; 100];
        // MSE 0.01 -> 20 dB.
        assert_relative_eq!(psnr(&a, &b).unwrap(), 20.0, epsilon = 1e-4);
        assert_eq!(psnr(&a, &a), Some(f64::INFINITY));
        assert!(psnr(&[f32::NAN], &[0.0]).is_none());
    }
}
