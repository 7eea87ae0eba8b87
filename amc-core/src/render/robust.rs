//! Ghost-free averaging: each aligned frame's pixel is weighted by how well it
//! agrees with the newest frame.
//!
//! The plain average of the window's aligned frames removes noise from the
//! static scene, but anything that moves relative to the scene (a hand, a car,
//! the foreground a rotation cannot align) appears once per frame: ghosts. As
//! in burst-photography merges (Hasinoff et al. 2016, "Burst photography for
//! high dynamic range and low-light imaging on mobile cameras"; Wronski et al.
//! 2019), the newest frame is the reference and every other frame's sample
//! counts by its agreement with it. With `s_f` a frame's 8.8 fixed-point sample
//! and `d_f = max over channels |s_f - s_ref|`,
//! ```text
//! w_ref = 16,   w_f = clamp(16 (2T - d_f) / T, 0, 16),   out = sum_f w_f s_f / sum_f w_f
//! ```
//! full weight up to a difference of `T` (the `deghost` threshold, 8.8), none
//! from `2T`, linear between (a hard cut would flicker where the difference
//! hovers at the threshold). Static scene differs by noise only and is
//! averaged; a mover differs by its contrast and comes from the newest frame
//! alone; so does an edge that the rotation leaves misaligned by a fraction of
//! a pixel (it would otherwise blur). Where the newest frame does not cover a
//! pixel there is nothing to agree with, and the covering frames are averaged
//! plainly. Weights are integers (4 bits) and the sums exact, so the merge is
//! the same bits on every target; it runs after the row kernels have sampled
//! each frame, as plain integer loops that the compiler vectorizes (compiled a
//! second time for AVX2, chosen at run time; `simd128` builds vectorize them
//! for wasm).
//!
//! The per-pixel difference (not a tile's, as the burst merges use) keeps the
//! cost at a few integer operations per sample: noise in the difference only
//! lowers some static pixels' weights a little, the ramp keeps that smooth.

/// Weights of the ghost-free average, from the `deghost` threshold.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Deghost {
    /// `2T`, 8.8 fixed point: the difference from which a sample counts nothing.
    zero_at: i32,
    /// `16 * 2^16 / T`: the ramp's slope in 16.16 fixed point.
    slope: i32,
}

/// Weight of a sample that agrees fully (and of the reference's).
pub const FULL_WEIGHT: u32 = 16;

/// Largest `deghost` threshold, levels of 255 (differences beyond it are
/// movers or misalignment in any footage; the range of the option).
pub const MAX_DEGHOST: f64 = 64.0;

impl Deghost {
    /// Weights for a threshold of `levels` (of 255: a difference up to it
    /// counts fully, from twice it not at all); `None` for 0, the plain
    /// average. `levels` is clamped to 1/256..=[`MAX_DEGHOST`].
    pub fn new(levels: f64) -> Option<Self> {
        if levels.is_nan() || levels <= 0.0 {
            return None;
        }
        let t = (levels * 256.0).round().clamp(1.0, MAX_DEGHOST * 256.0) as i32;
        Some(Self {
            zero_at: 2 * t,
            // Rounded up, so that a difference of exactly `T` still weighs 16.
            slope: (16u32 << 16).div_ceil(t as u32) as i32,
        })
    }

    /// `(2T, slope)`: the vector kernels' copy of [`Deghost::weight`].
    // Only the vector kernels read it: unused where there are none (wasm32
    // without simd128).
    #[cfg_attr(
        not(any(
            target_arch = "x86_64",
            all(target_arch = "wasm32", target_feature = "simd128")
        )),
        allow(dead_code)
    )]
    pub(crate) fn constants(self) -> (i32, i32) {
        (self.zero_at, self.slope)
    }

    /// The weight (0..=16) of a sample differing by `d` (8.8) from the reference.
    /// `(2T - d) * slope <= 2T (2^20 / T + 1) <= 2^21 + 2^15`: no overflow.
    #[inline(always)]
    pub fn weight(self, d: u32) -> u32 {
        let d = d.min(1 << 16) as i32;
        ((((self.zero_at - d).max(0)) * self.slope) >> 16).min(FULL_WEIGHT as i32) as u32
    }

    multiversion! {
        /// The weighted sums of one plane (one value per pixel): for each of the
        /// `n` pixels, `sum = sum_f w_f s_f` and `weight = sum_f w_f` over the
        /// frames covering it (`covered[f][i]` 1, else 0 with `values[f][i]` 0),
        /// `values[reference]` the newest frame's. (Compiled for AVX2 where the
        /// CPU has it: the compiler vectorizes its integer loops eight pixels
        /// wide.)
        pub fn merge_plane<S, C>(
            [] self,
            values: &[&[S]],
            covered: &[&[C]],
            reference: usize,
            n: usize,
            sum: &mut [u32],
            weight: &mut [u32],
        ) where [S: Copy + Into<u32>, C: Copy + Into<u32>] => merge_plane_body {
            merge_plane_avx2: "avx2" if "avx2",
        }
    }

    #[inline(always)]
    fn merge_plane_body<S, C>(
        self,
        values: &[&[S]],
        covered: &[&[C]],
        reference: usize,
        n: usize,
        sum: &mut [u32],
        weight: &mut [u32],
    ) where
        S: Copy + Into<u32>,
        C: Copy + Into<u32>,
    {
        let (sum, weight) = (&mut sum[..n], &mut weight[..n]);
        let (rv, rc) = (&values[reference][..n], &covered[reference][..n]);
        for (((s, w), &v), &c) in sum.iter_mut().zip(weight.iter_mut()).zip(rv).zip(rc) {
            let c: u32 = c.into();
            *w = FULL_WEIGHT * c;
            *s = FULL_WEIGHT * c * v.into();
        }
        for (f, (vals, cov)) in values.iter().zip(covered).enumerate() {
            if f == reference {
                continue;
            }
            let (vals, cov) = (&vals[..n], &cov[..n]);
            for i in 0..n {
                let (v, r): (u32, u32) = (vals[i].into(), rv[i].into());
                let agree = self.weight(v.abs_diff(r));
                let w = cov[i].into()
                    * if rc[i].into() != 0 {
                        agree
                    } else {
                        FULL_WEIGHT
                    };
                sum[i] += w * v;
                weight[i] += w;
            }
        }
    }

    multiversion! {
        /// [`Deghost::merge_plane`] for three channels: `values[f][ch]` holds
        /// channel `ch` of pixel `i` at index `i * stride` (separate rows: stride
        /// 1; interleaved RGB: the slice starting at the channel, stride 3), and
        /// `sum[ch]` receives that channel's sums, pixel `i` at `i`. The difference
        /// is the largest of the three channels'.
        #[allow(clippy::too_many_arguments)]
        pub fn merge_rgb<S, C>(
            [] self,
            values: &[[&[S]; 3]],
            stride: usize,
            covered: &[&[C]],
            reference: usize,
            n: usize,
            sum: [&mut [u32]; 3],
            weight: &mut [u32],
        ) where [S: Copy + Into<u32>, C: Copy + Into<u32>] => merge_rgb_body {
            merge_rgb_avx2: "avx2" if "avx2",
        }
    }

    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn merge_rgb_body<S, C>(
        self,
        values: &[[&[S]; 3]],
        stride: usize,
        covered: &[&[C]],
        reference: usize,
        n: usize,
        sum: [&mut [u32]; 3],
        weight: &mut [u32],
    ) where
        S: Copy + Into<u32>,
        C: Copy + Into<u32>,
    {
        let [sr, sg, sb] = sum;
        let (sr, sg, sb, weight) = (&mut sr[..n], &mut sg[..n], &mut sb[..n], &mut weight[..n]);
        let ([rr, rg, rb], rc) = (values[reference], covered[reference]);
        for i in 0..n {
            let c: u32 = rc[i].into();
            weight[i] = FULL_WEIGHT * c;
            sr[i] = FULL_WEIGHT * c * rr[i * stride].into();
            sg[i] = FULL_WEIGHT * c * rg[i * stride].into();
            sb[i] = FULL_WEIGHT * c * rb[i * stride].into();
        }
        for (f, ([vr, vg, vb], cov)) in values.iter().zip(covered).enumerate() {
            if f == reference {
                continue;
            }
            for i in 0..n {
                let j = i * stride;
                let (r, g, b): (u32, u32, u32) = (vr[j].into(), vg[j].into(), vb[j].into());
                let d = r
                    .abs_diff(rr[j].into())
                    .max(g.abs_diff(rg[j].into()))
                    .max(b.abs_diff(rb[j].into()));
                let agree = self.weight(d);
                let w = cov[i].into()
                    * if rc[i].into() != 0 {
                        agree
                    } else {
                        FULL_WEIGHT
                    };
                sr[i] += w * r;
                sg[i] += w * g;
                sb[i] += w * b;
                weight[i] += w;
            }
        }
    }
}

/// `round(sum / (256 weight))` for weighted 8.8 sums, `fill` where the weight
/// is 0 (no frame covers the pixel).
#[inline(always)]
pub fn weighted_average(sum: u32, weight: u32, fill: u8) -> u8 {
    if weight == 0 {
        fill
    } else {
        (sum as f32 * (1.0 / (256.0 * weight as f32)) + 0.5) as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_ramp_from_the_threshold_to_twice_it() {
        let g = Deghost::new(8.0).unwrap();
        let t = 8 * 256;
        assert_eq!(g.weight(0), 16);
        assert_eq!(g.weight(t), 16);
        assert_eq!(g.weight(t + t / 2), 8);
        assert_eq!(g.weight(2 * t), 0);
        assert_eq!(g.weight(u32::MAX), 0);
        // Monotone in the difference.
        let w: Vec<u32> = (0..70_000).step_by(7).map(|d| g.weight(d)).collect();
        assert!(w.windows(2).all(|p| p[1] <= p[0]));
        assert_eq!(Deghost::new(0.0), None);
        assert_eq!(Deghost::new(f64::NAN), None);
        // The smallest and largest thresholds stay within i32.
        assert_eq!(Deghost::new(1e-9).unwrap().weight(0), 16);
        assert_eq!(Deghost::new(1e9).unwrap().weight(64 * 256), 16);
        // A threshold that does not divide 2^20 still gives 16 at `T`.
        let odd = Deghost::new(7.8125 + 1.0 / 256.0).unwrap();
        assert_eq!(odd.weight(2001), 16);
        assert_eq!(odd.weight(4002), 0);
    }

    /// Agreeing frames are averaged, a disagreeing one is left out, and
    /// without the reference every covering frame counts.
    #[test]
    fn merge_keeps_what_agrees_with_the_newest_frame() {
        let g = Deghost::new(4.0).unwrap();
        let s = |x: u32| x * 256;
        // Pixel 0: frames 10, 12, 200 (an outlier), reference 11.
        // Pixel 1: the reference does not cover it; frames 50 and 70.
        let values: [&[u32]; 4] = [&[s(10), s(50)], &[s(12), s(70)], &[s(200), 0], &[s(11), 0]];
        let covered: [&[u8]; 4] = [&[1, 1], &[1, 1], &[1, 0], &[1, 0]];
        let (mut sum, mut weight) = ([0u32; 2], [0u32; 2]);
        g.merge_plane(&values, &covered, 3, 2, &mut sum, &mut weight);
        assert_eq!(weight, [48, 32]);
        assert_eq!(weighted_average(sum[0], weight[0], 0), 11);
        assert_eq!(weighted_average(sum[1], weight[1], 0), 60);
        // The same through the three-channel merge (channels equal) and interleaved.
        let inter: Vec<Vec<u32>> = values
            .iter()
            .map(|v| v.iter().flat_map(|&x| [x, x, x]).collect())
            .collect();
        let rgb: Vec<[&[u32]; 3]> = inter.iter().map(|v| [&v[..], &v[1..], &v[2..]]).collect();
        let (mut r, mut gg, mut b, mut w3) = ([0u32; 2], [0u32; 2], [0u32; 2], [0u32; 2]);
        g.merge_rgb(&rgb, 3, &covered, 3, 2, [&mut r, &mut gg, &mut b], &mut w3);
        assert_eq!((r, gg, b, w3), (sum, sum, sum, weight));
    }
}
