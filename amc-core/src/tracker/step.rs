//! The inverse-compositional Gauss-Newton step ([`Eval::pose_step`]).
//!
//! Warp the *template* by a small rotation `delta in so(3)`:
//! `W(p; delta) = pi(K exp(delta) x)`. With `exp(delta) x ~ x - [x]x delta` and
//! `u = fx x + s y + cx`, `v = fy y + cy` the Jacobian at `delta = 0` is
//! ```text
//! dx/d delta = (-x y, 1 + x^2, -y)        dy/d delta = (-(1 + y^2), x y, x)
//! du/d delta = fx dx/d delta + s dy/d delta      dv/d delta = fy dy/d delta
//! ```
//! so the steepest-descent image `SD_p = grad T(p) . dW/d delta` and the
//! Gauss-Newton Hessian `H = sum_p w_p SD_p SD_p^T` depend on the template only
//! (precomputed at each template reset). With residual `e_p = I(W(p; R)) - T(p)`:
//! ```text
//! delta = H^-1 sum_p w_p SD_p e_p,        R <- exp(delta) R
//! ```
//! (`T(exp(delta) y) = I(R^T exp(-delta) y)` for all `y`, hence
//! `R_new^T = R^T exp(-delta)`.)

use super::eval::Eval;
use super::shutter_prior::ReadoutPrior;
use super::state::Pose;
use crate::shutter::{IntraFrame, INTRA_TERMS};
use crate::so3::{self, Tangent};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Weight of the readout path's step in the convergence test: its terms
/// converge more slowly than the rotation (the bend and the S-shape are weakly
/// seen), and a move of the rows by `convergence_px / INTRA_TOLERANCE_SCALE` is
/// still far below what the estimate can resolve (see
/// `docs/core-history.md#tracker-intra-tolerance-scale`).
pub(super) const INTRA_TOLERANCE_SCALE: f64 = 0.1;

/// One Gauss-Newton step: the rotation's (inverse compositional) and the
/// intra-frame motion's (additive; zero when it is not estimated).
#[derive(Clone, Copy, Debug)]
pub(super) struct Step {
    pub(super) delta: Tangent,
    /// Steps of the readout path's terms (`phi, psi, chi`).
    pub(super) dterms: [Tangent; INTRA_TERMS],
}

impl Step {
    /// The largest angle the step moves a ray by (term `k` acts at most
    /// `2^-(k+1)` at `s = 1/2`).
    pub(super) fn angle(&self) -> f64 {
        let intra: f64 = (self.dterms.iter())
            .enumerate()
            .map(|(k, d)| d.norm() * 0.5f64.powi(k as i32 + 1))
            .sum();
        self.delta.norm().max(intra * INTRA_TOLERANCE_SCALE)
    }

    /// `pose` moved by `scale` times this step.
    pub(super) fn apply(&self, pose: &Pose, scale: f64) -> Pose {
        let mut terms = pose.intra.terms();
        for (t, d) in terms.iter_mut().zip(&self.dterms) {
            *t += d * scale;
        }
        Pose {
            r: so3::exp(&(self.delta * scale)) * pose.r,
            intra: IntraFrame::from_terms(terms),
        }
    }
}

impl Eval {
    /// Solves the 3x3 Gauss-Newton system; `None` when it is degenerate.
    pub(super) fn step(&self) -> Option<Tangent> {
        let h = &self.h;
        let m = Matrix3::new(h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5]);
        // A whisper of Levenberg damping keeps textureless axes from exploding.
        let damped = m + Matrix3::identity() * (1e-9 * m.trace() + 1e-18);
        let d = damped
            .cholesky()?
            .solve(&Vector3::new(self.g[0], self.g[1], self.g[2]));
        d.iter().all(|v| v.is_finite()).then_some(d)
    }

    /// The step of `pose`'s parameters: the rotation only, or with the
    /// readout path's terms (`intra`).
    ///
    /// With `P = R_{k,j}^T`, the residual's Jacobian at a point that landed
    /// on readout fraction `s` is `[SD, s P SD, s^2 P SD, s^3 P SD]`: moving
    /// term `k` by `d` turns the ray by `s^k d` in the current camera, which
    /// is the template-side rotation `s^k R d` (to first order), so with
    /// `Sk = sum w s^k SD SD^T` and `Gk = sum w s^k SD e`
    /// ```text
    /// H_ab = P_a S_(a+b) P_b^T,    g_a = P_a G_a      (P_0 = I, P_a = P)
    /// ```
    pub(super) fn pose_step(
        &self,
        pose: &Pose,
        intra: bool,
        terms: usize,
        prior: Option<&ReadoutPrior>,
    ) -> Option<Step> {
        if !intra {
            return self.step().map(|delta| Step {
                delta,
                dterms: [Tangent::zeros(); INTRA_TERMS],
            });
        }
        pub(super) const N: usize = 3 * (INTRA_TERMS + 1);
        let sym = |h: &[f64; 6]| Matrix3::new(h[0], h[1], h[2], h[1], h[3], h[4], h[2], h[4], h[5]);
        let p = *pose.r.matrix();
        let side = |a: usize| if a == 0 { Matrix3::identity() } else { p };
        let sk = |k: usize| {
            if k == 0 {
                sym(&self.h)
            } else {
                sym(&self.hs[k - 1])
            }
        };
        let gk = |k: usize| Vector3::from(if k == 0 { self.g } else { self.gs[k - 1] });
        let mut h = SMatrix::<f64, N, N>::zeros();
        let mut g = SVector::<f64, N>::zeros();
        for a in 0..=INTRA_TERMS {
            for b in 0..=INTRA_TERMS {
                let m = side(a) * sk(a + b) * side(b).transpose();
                h.fixed_view_mut::<3, 3>(3 * a, 3 * b).copy_from(&m);
            }
            g.fixed_rows_mut::<3>(3 * a).copy_from(&(side(a) * gk(a)));
        }
        // Levenberg damping, stronger on the readout terms than on the
        // rotation: they are weakly seen where texture is sparse.
        let damp = 1e-6 * h.trace() / N as f64 + 1e-18;
        for i in 0..N {
            h[(i, i)] += damp * if i < 3 { 1e-3 } else { 1.0 };
        }
        // Terms beyond `terms` are held (their rows pinned).
        let pin = 1e9 * h.trace();
        for i in 3 * (terms + 1)..N {
            h[(i, i)] += pin;
        }
        // The prior on the readout path (see [`ReadoutPrior`]).
        if let Some(prior) = prior {
            let dev = prior.deviation(&pose.intra);
            for k in 0..INTRA_TERMS {
                for a in 0..3 {
                    let i = 3 * (k + 1) + a;
                    h[(i, i)] += prior.weight;
                    g[i] -= prior.weight * dev[k][a];
                }
            }
        }
        let d = h.cholesky()?.solve(&g);
        if !d.iter().all(|v| v.is_finite()) {
            return None;
        }
        Some(Step {
            delta: d.fixed_rows::<3>(0).into_owned(),
            dterms: std::array::from_fn(|k| d.fixed_rows::<3>(3 * (k + 1)).into_owned()),
        })
    }
}
