//! Pass 3 of an evaluation, per point: the Huber loss and the IRLS terms of
//! the Gauss-Newton system (the tracker's `Eval`).
//!
//! Per point first, into arrays of a chunk's length, and the sums over the
//! chunk afterwards, in lanes ([`crate::lanes`]): with running `f32` sums in
//! it, the loop ran scalar (one serial chain of additions per sum) and was a
//! third of the pass.

use crate::lanes;

/// Points per chunk of the evaluation loop (fits L1 with room to spare).
pub(super) const CHUNK: usize = 64;

/// A chunk's per-point terms (up to [`CHUNK`] points): the Huber loss,
/// validity and IRLS weight of each residual, and the weighted residual times
/// each steepest-descent image.
pub(super) struct IrlsTerms {
    /// Robust loss (0 where invalid).
    pub rho: [f32; CHUNK],
    /// 1 where the residual is valid, else 0.
    pub ok: [f32; CHUNK],
    /// IRLS weight (0 where invalid).
    pub wt: [f32; CHUNK],
    /// `wt e sd[a]` for each rotation axis `a`.
    pub we: [[f32; CHUNK]; 3],
}

impl Default for IrlsTerms {
    fn default() -> Self {
        Self {
            rho: [0.0; CHUNK],
            ok: [0.0; CHUNK],
            wt: [0.0; CHUNK],
            we: [[0.0; CHUNK]; 3],
        }
    }
}

impl IrlsTerms {
    /// The chunk's robust loss, squared residual and valid count (`pe`: the
    /// residuals as [`irls_terms`] left them, 0 where invalid).
    pub fn sums(&self, pe: &[f32]) -> (f64, f64, u32) {
        let len = pe.len();
        (
            lanes::sum(&self.rho[..len]) as f64,
            lanes::dot(pe, pe) as f64,
            lanes::sum(&self.ok[..len]) as u32,
        )
    }
}

/// Fills `t` for the residuals `pe` (NaN: invalid; replaced by the residual
/// [`huber`] keeps, 0 where invalid) with steepest-descent images `sd`.
#[inline(always)]
pub(super) fn irls_terms(pe: &mut [f32], sd: [&[f32]; 3], c: f32, t: &mut IrlsTerms) {
    let len = pe.len().min(CHUNK);
    let [sd0, sd1, sd2] = sd.map(|a| &a[..len]);
    for q in 0..len {
        let (valid, e, rho, wt) = huber(pe[q], c);
        pe[q] = e;
        t.rho[q] = rho;
        t.ok[q] = if valid { 1.0 } else { 0.0 };
        t.wt[q] = wt;
        let wte = wt * e;
        t.we[0][q] = sd0[q] * wte;
        t.we[1][q] = sd1[q] * wte;
        t.we[2][q] = sd2[q] * wte;
    }
}

/// The IRLS-weighted outer products `wt sd sd^T` of a chunk's first `len`
/// points, upper triangle in the order of the tracker's `Eval::h`.
#[inline(always)]
pub(super) fn outer_products(
    sd: [&[f32]; 3],
    wt: &[f32; CHUNK],
    len: usize,
    outer: &mut [[f32; CHUNK]; 6],
) {
    let len = len.min(CHUNK);
    let [sd0, sd1, sd2] = sd.map(|a| &a[..len]);
    for q in 0..len {
        let (s0, s1, s2) = (sd0[q], sd1[q], sd2[q]);
        let (w0, w1, w2) = (wt[q] * s0, wt[q] * s1, wt[q] * s2);
        outer[0][q] = w0 * s0;
        outer[1][q] = w0 * s1;
        outer[2][q] = w0 * s2;
        outer[3][q] = w1 * s1;
        outer[4][q] = w1 * s2;
        outer[5][q] = w2 * s2;
    }
}

/// Huber loss of residual `e` (NaN: invalid) with threshold `c`: whether it
/// is valid, the residual (0 when not), the loss and the IRLS weight.
///
/// Branch-free, so that the loops calling it vectorize: with `m = min(|e|, c)`
/// the loss is `m (|e| - m / 2)` (`e^2 / 2` for an inlier, `c (|e| - c / 2)`
/// beyond) and the weight `c / max(|e|, c)` (exactly 1 for an inlier); both
/// round exactly as the two-branch forms do.
#[inline(always)]
fn huber(e: f32, c: f32) -> (bool, f32, f32, f32) {
    let valid = e.is_finite();
    let e = if valid { e } else { 0.0 };
    let ae = e.abs();
    // Plain compares, not `f32::min`/`max`: `ae` is never NaN, and their NaN
    // handling kept the loops scalar.
    let m = if ae < c { ae } else { c };
    let rho = m * (ae - 0.5 * m);
    let wt = if valid {
        c / if ae > c { ae } else { c }
    } else {
        0.0
    };
    (valid, e, rho, wt)
}
