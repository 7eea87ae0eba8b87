//! One pass over a level's template pixels: the robust loss and the
//! IRLS-weighted Gauss-Newton sums, with a global shutter (here) or a rolling
//! one (`rolling.rs`), compiled for the widest instruction set the CPU has.
//!
//! Robustness:
//! * Huber loss `rho` with IRLS weights `w_p = min(1, c / |e_p|)`: moving objects,
//!   the dashboard of a car, transmission glitches.
//! * Only pixels valid in both images count (`NaN` marks invalid pixels).

use super::irls::{irls_terms, outer_products, IrlsTerms, CHUNK};
use super::residuals::residuals;
use super::state::Pose;
use super::state::WarmStart;
use super::Tracker;
use crate::image::GrayImage;
use crate::lanes;
use crate::shutter::INTRA_TERMS;
use crate::so3::Rot;

/// Sums of one pass over a level's template pixels.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Eval {
    /// Sum of the robust loss.
    pub(super) loss: f64,
    /// Sum of squared residuals.
    pub(super) sq: f64,
    pub(super) n: u32,
    pub(super) g: [f64; 3],
    /// Upper triangle of H: xx, xy, xz, yy, yz, zz.
    pub(super) h: [f64; 6],
    /// Rolling shutter: `sum w s^k SD SD^T` for `k = 1..=2N` (upper
    /// triangles) and `sum w s^k SD e` for `k = 1..=N` (`N` the terms of the
    /// readout path), `s` the readout fraction of the row each point landed on
    /// (zero with a global shutter).
    pub(super) hs: [[f64; 6]; 2 * INTRA_TERMS],
    pub(super) gs: [[f64; 3]; INTRA_TERMS],
}

impl Eval {
    /// Adds a chunk's robust loss, squared residual and valid count
    /// ([`IrlsTerms::sums`]).
    pub(super) fn add_chunk_sums(&mut self, (loss, sq, n): (f64, f64, u32)) {
        self.loss += loss;
        self.sq += sq;
        self.n += n;
    }

    pub(super) fn mean_loss(&self) -> f64 {
        if self.n == 0 {
            f64::INFINITY
        } else {
            self.loss / self.n as f64
        }
    }
}

impl Tracker {
    multiversion! {
        /// One pass over a level's template pixels at `pose`, with the global-
        /// or the rolling-shutter model. `warm_start`: the level's Gauss-Newton
        /// iteration's (a rolling shutter's evaluations after the level's first
        /// start from it, see [`WarmStart`]); `None` for one-off evaluations.
        /// Compiled for AVX2 where the CPU has it: the per-point loops then
        /// vectorize eight points wide instead of four, and the sums are the
        /// same bits ([`lanes`] fixes their order).
        pub(super) fn evaluate(
            [&] self,
            level: usize,
            img: &GrayImage,
            pose: &Pose,
            warm_start: Option<&mut WarmStart>,
        ) -> Eval => evaluate_body {
            evaluate_avx2: "avx2" if "avx2",
        }
    }

    /// [`Self::evaluate`] for whichever instruction set it is compiled.
    #[inline(always)]
    pub(super) fn evaluate_body(
        &self,
        level: usize,
        img: &GrayImage,
        pose: &Pose,
        warm_start: Option<&mut WarmStart>,
    ) -> Eval {
        match &self.rolling {
            None => self.evaluate_global(level, img, &pose.r),
            Some(rows) => {
                let terms = self.level_terms(level);
                self.evaluate_rolling(level, img, pose, rows, terms, warm_start)
            }
        }
    }

    /// One pass over a level's template pixels at rotation `r = R_{k,j}`:
    /// robust loss, and the IRLS-weighted Gauss-Newton system.
    #[inline(always)]
    pub(super) fn evaluate_global(&self, level: usize, img: &GrayImage, r: &Rot) -> Eval {
        let tpl = &self.template[level];
        let Some(k) = tpl.k else {
            return Eval::default();
        };
        let m = r.matrix().transpose().map(|v| v as f32);
        let (w, h) = (img.width, img.height);
        if w < 2 || h < 2 {
            return Eval::default();
        }
        let c = self.params.huber_delta as f32;
        let mut ev = Eval::default();
        let (mut pu, mut pv, mut pe) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
        let mut terms = IrlsTerms::default();
        let mut outer = [[0f32; CHUNK]; 6];
        // The matrix's and the gradient's lane accumulators, added up once
        // after the last chunk (see [`lanes::dot_into`]).
        let (mut h_lanes, mut g_lanes) = ([[0f32; lanes::LANES]; 6], [[0f32; lanes::LANES]; 3]);
        let m = [
            m[(0, 0)],
            m[(0, 1)],
            m[(0, 2)],
            m[(1, 0)],
            m[(1, 1)],
            m[(1, 2)],
            m[(2, 0)],
            m[(2, 1)],
            m[(2, 2)],
        ];
        let n_pts = tpl.xs.len();
        let mut lo = 0;
        while lo < n_pts {
            let hi = (lo + CHUNK).min(n_pts);
            // (`min`: tells the compiler `len <= CHUNK`, see the rolling pass.)
            let len = (hi - lo).min(CHUNK);
            let (xs, ys) = (&tpl.xs[lo..hi], &tpl.ys[lo..hi]);
            // Pass 1 (branch-free, vectorizes): project the rotated rays.
            // Rays behind the camera get an out-of-image coordinate.
            for q in 0..len {
                let (x, y) = (xs[q], ys[q]);
                (pu[q], pv[q]) = k.project(
                    m[0] * x + m[1] * y + m[2],
                    m[3] * x + m[4] * y + m[5],
                    m[6] * x + m[7] * y + m[8],
                );
            }
            // Pass 2 (gathers): bilinear residuals, NaN where invalid.
            residuals(img, &pu[..len], &pv[..len], &tpl.tv[lo..hi], &mut pe[..len]);
            // Pass 3: Huber loss and IRLS terms per point, summed in lanes.
            let sd = tpl.sd.each_ref().map(|a| &a[lo..hi]);
            irls_terms(&mut pe[..len], sd, c, &mut terms);
            outer_products(sd, &terms.wt, len, &mut outer);
            ev.add_chunk_sums(terms.sums(&pe[..len]));
            for (o, acc) in outer.iter().zip(&mut h_lanes) {
                lanes::sum_into(&o[..len], acc);
            }
            for (v, acc) in terms.we.iter().zip(&mut g_lanes) {
                lanes::sum_into(&v[..len], acc);
            }
            lo = hi;
        }
        ev.h = h_lanes.map(|a| lanes::lanes_total(&a));
        ev.g = g_lanes.map(|a| lanes::lanes_total(&a));
        ev
    }
}
