//! The evaluation through a rolling shutter: each template ray projected into
//! the current frame at the time of the row it lands on.
//!
//! ## Rolling shutter With [`Tracker::set_rolling`], each frame's motion during
//! its readout, `a(s) = s phi + s^2 psi + s^3 chi + s^4 xi`
//! ([`IntraFrame`](crate::shutter::IntraFrame), `s` the readout fraction of a
//! row), is estimated with its mid-readout rotation:
//! * template rays are rectified into the template's mid-readout camera,
//!   `y = exp(a_k(s_p)) x_p`;
//! * a ray lands in the current frame at `pi(K exp(-a(s)) R^T y)`, `s` the
//!   readout fraction of the landing row (a fixed point: two steps from the
//!   mid-readout projection and an extrapolation; a level's later evaluations
//!   take one step from the last landing, and keep its first Gauss-Newton
//!   matrix until a step moves the points far, [`WarmStart`]); through a
//!   distorted lens the landing row's readout fraction is sampled from a
//!   table per level ([`RowTime::level_table`]);
//! * the Gauss-Newton step has up to 15 parameters ([`Eval::pose_step`]): the
//!   rotation's inverse-compositional step and additive steps of the terms,
//!   whose Jacobians are the rotation's times `s^k` (turned into the current
//!   camera), on the finest [`INTRA_LEVELS`](super::pace::INTRA_LEVELS) levels
//!   at a fast pace (all terms on the finest, all but `xi` on the next, `phi`
//!   on the coarser ones, [`Tracker::level_terms`]);
//! * alignment sees only differences of readout motion between a frame and
//!   its template: the absolute value is pinned by time ([`Gauge`](super::gauge::Gauge));
//! * fast motion estimates `phi, psi, chi`, and `xi` where the path bends
//!   enough to need it ([`QUARTIC_MIN_PX`](super::pace::QUARTIC_MIN_PX)); slow
//!   motion estimates `phi` only, under a prior
//!   ([`PACE_SWITCH`](super::pace::PACE_SWITCH)) that grows where the readout
//!   motion is too small to see
//!   ([`OBSERVABLE_READOUT_PX`](super::shutter_prior::OBSERVABLE_READOUT_PX));
//!   there templates are rectified with the motion the rate predicts, so what
//!   the estimate absorbs (looming) cannot add up template after template.

use super::eval::Eval;
use super::irls::{irls_terms, outer_products, IrlsTerms, CHUNK};
use super::landing::{land_at, row_times_into};
use super::residuals::residuals;
use super::state::Pose;
use super::state::WarmStart;
use super::Tracker;
use crate::image::GrayImage;
use crate::lanes;
use crate::shutter::{RowTime, INTRA_TERMS};

/// A rolling-shutter evaluation after a step that moved the points by more
/// than this (pixels of the level) sums its Gauss-Newton matrix afresh
/// instead of keeping the level's first ([`WarmStart`]): far from the optimum
/// the landing rows and the robust weights the matrix is made of move with
/// the pose (see `docs/core-history.md#tracker-matrix-refresh-px`).
pub(super) const MATRIX_REFRESH_PX: f64 = 0.3;

impl Tracker {
    /// [`Tracker::evaluate_global`] through a rolling shutter: each template
    /// ray (rectified into the template's mid-readout camera) is projected
    /// into the current frame at the time of the row it lands on (fixed-point
    /// steps from the mid-readout guess, [`crate::shutter::project_rolling`]),
    /// and the sums carry that row's readout fraction for the intra-frame
    /// terms of [`Eval::pose_step`].
    ///
    /// The readout rotation `exp(-a)`, `a = s phi + ... + s^4 xi`, is applied to
    /// third order, `z + b x z + (b x (b x z)) / 2 + (b x (b x (b x z))) / 6`
    /// with `b = -a`: its error `|a|^4 / 24` is 3e-7 rad for a 6 deg turn
    /// across the readout (300 deg/s over 20 ms).
    #[inline(always)]
    pub(super) fn evaluate_rolling(
        &self,
        level: usize,
        img: &GrayImage,
        pose: &Pose,
        rows: &RowTime,
        terms: usize,
        warm_start: Option<&mut WarmStart>,
    ) -> Eval {
        let table = self.row_tables.get(level);
        let row_times =
            |pu: &[f32], pv: &[f32], ps: &mut [f32]| row_times_into(rows, table, level, pu, pv, ps);
        self.evaluate_rolling_with(level, img, pose, terms, warm_start, row_times)
    }

    /// [`Tracker::evaluate_rolling`] with `row_times(pu, pv, ps)`, which
    /// writes the readout fraction of each level pixel `(pu, pv)` into `ps`
    /// (a chunk at a time, so that a table is sampled by the vector gathers
    /// and the passes around it stay vectorized). The intra-frame sums are
    /// accumulated for the first `n_terms` terms of the readout path (those
    /// the level estimates; none: 0).
    #[inline(always)]
    pub(super) fn evaluate_rolling_with<T: Fn(&[f32], &[f32], &mut [f32])>(
        &self,
        level: usize,
        img: &GrayImage,
        pose: &Pose,
        n_terms: usize,
        mut warm_start: Option<&mut WarmStart>,
        row_times: T,
    ) -> Eval {
        let tpl = &self.template[level];
        let Some(k) = tpl.k else {
            return Eval::default();
        };
        let (w, h) = (img.width, img.height);
        if w < 2 || h < 2 || tpl.zs.len() != tpl.xs.len() {
            return Eval::default();
        }
        let mm = pose.r.matrix().transpose().map(|v| v as f32);
        let m: [f32; 9] = std::array::from_fn(|i| mm[(i / 3, i % 3)]);
        let path = pose
            .intra
            .terms()
            .map(|t| [t.x as f32, t.y as f32, t.z as f32]);
        let c = self.params.huber_delta as f32;
        let mut ev = Eval::default();
        let (mut pu, mut pv, mut pe, mut ps) =
            ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
        let (mut rx, mut ry, mut rz) = ([0f32; CHUNK], [0f32; CHUNK], [0f32; CHUNK]);
        let (mut dv, mut gain) = ([0f32; CHUNK], [0f32; CHUNK]);
        let mut terms = IrlsTerms::default();
        let mut outer = [[0f32; CHUNK]; 6];
        let n_pts = tpl.xs.len();
        // Warm: start from the level's first evaluation (see [`WarmStart`]).
        let warm = match warm_start.as_deref_mut() {
            Some(l) if l.valid && l.u.len() == n_pts => true,
            Some(l) => {
                l.u.resize(n_pts, 0.0);
                l.v.resize(n_pts, 0.0);
                l.gain.resize(n_pts, 0.0);
                false
            }
            None => false,
        };
        let reuse = warm && !warm_start.as_deref().is_some_and(|l| l.refresh);
        // A one-off evaluation (a start candidate's, the recovery grid's)
        // is compared by its loss alone: the Gauss-Newton sums are skipped.
        let loss_only = warm_start.is_none();
        // The moments' lane accumulators: the matrix's `s^p` (p = 0..=2N) and
        // the gradient's (p = 0..=N).
        let mut h_lanes = [[[0f32; lanes::LANES]; 6]; 2 * INTRA_TERMS + 1];
        let mut g_lanes = [[[0f32; lanes::LANES]; 3]; INTRA_TERMS + 1];
        let mut lo = 0;
        while lo < n_pts {
            let hi = (lo + CHUNK).min(n_pts);
            // (`min`: tells the compiler `len <= CHUNK`, which lifts the
            // bounds checks out of the loops below and lets them vectorize.)
            let len = (hi - lo).min(CHUNK);
            // Pass 1 (branch-free loops over the chunk, which vectorize):
            // rotate the rays to the mid-readout pose.
            let (xs, ys, zs) = (&tpl.xs[lo..hi], &tpl.ys[lo..hi], &tpl.zs[lo..hi]);
            for q in 0..len {
                let (x, y, z) = (xs[q], ys[q], zs[q]);
                rx[q] = m[0] * x + m[1] * y + m[2] * z;
                ry[q] = m[3] * x + m[4] * y + m[5] * z;
                rz[q] = m[6] * x + m[7] * y + m[8] * z;
            }
            // Two fixed-point steps from the mid-readout guess, then Aitken's
            // extrapolation along the second.
            //
            // The step `y -> pi_y(exp(-a(s(y))) z)` moves the row by about `kappa = f
            // |a'(s)| / H` per row of change, so the iterates approach the landing point
            // geometrically, `p_n - p* ~ kappa^n (p_0 - p*)`, and from the last two moves
            // `kappa = dy_2 / dy_1` and `p* = p_2 + kappa / (1 - kappa) (p_2 - p_1)`
            // (both coordinates follow the row's time, so both extrapolate alike).
            // Two plain steps leave a bias at fast motion; the extrapolation removes it
            // without a projection (see `docs/core-history.md#tracker-landing-extrapolation`).
            let land = |s: f32, q: usize| land_at(&k, &path, s, [rx[q], ry[q], rz[q]]);
            match warm_start.as_deref_mut() {
                Some(l) if warm => {
                    // One step from the last landing, extrapolated with its gain.
                    // (Sliced to `len`, not `lo..hi`: the compiler then sees
                    // every index in bounds and vectorizes the loop; with the
                    // check left in it ran a point at a time.)
                    let (lu, lv) = (&mut l.u[lo..][..len], &mut l.v[lo..][..len]);
                    let lg = &l.gain[lo..][..len];
                    row_times(lu, lv, &mut ps[..len]);
                    for q in 0..len {
                        let (u, v) = land(ps[q], q);
                        pu[q] = u + lg[q] * (u - lu[q]);
                        pv[q] = v + lg[q] * (v - lv[q]);
                        (lu[q], lv[q]) = (pu[q], pv[q]);
                    }
                    row_times(&pu[..len], &pv[..len], &mut ps[..len]);
                }
                cold => {
                    for q in 0..len {
                        (pu[q], pv[q]) = k.project(rx[q], ry[q], rz[q]);
                    }
                    row_times(&pu[..len], &pv[..len], &mut ps[..len]);
                    for q in 0..len {
                        let (u, v) = land(ps[q], q);
                        dv[q] = v - pv[q];
                        (pu[q], pv[q]) = (u, v);
                    }
                    row_times(&pu[..len], &pv[..len], &mut ps[..len]);
                    // A one-off evaluation (start candidates and the recovery
                    // grid, told apart on the coarsest level) stops after one
                    // step, which lands within a tenth of that level's pixel.
                    if !loss_only {
                        for q in 0..len {
                            let (u, v) = land(ps[q], q);
                            let (eu, ev) = (u - pu[q], v - pv[q]);
                            let ratio = if dv[q].abs() > 1e-4 {
                                (ev / dv[q]).clamp(-0.5, 0.5)
                            } else {
                                0.0
                            };
                            gain[q] = ratio / (1.0 - ratio);
                            pu[q] = u + gain[q] * eu;
                            pv[q] = v + gain[q] * ev;
                        }
                        row_times(&pu[..len], &pv[..len], &mut ps[..len]);
                        if let Some(l) = cold {
                            l.u[lo..hi].copy_from_slice(&pu[..len]);
                            l.v[lo..hi].copy_from_slice(&pv[..len]);
                            l.gain[lo..hi].copy_from_slice(&gain[..len]);
                        }
                    }
                }
            }
            // Pass 2 (gathers): bilinear residuals, NaN where invalid.
            residuals(img, &pu[..len], &pv[..len], &tpl.tv[lo..hi], &mut pe[..len]);
            // Pass 3: Huber loss and IRLS terms per point (a point whose row
            // time is not finite is invalid), then (estimating the readout
            // path) their moments in the rows' readout fractions, in lanes.
            for q in 0..len {
                pe[q] = if ps[q].is_finite() { pe[q] } else { f32::NAN };
            }
            let sd = tpl.sd.each_ref().map(|a| &a[lo..hi]);
            irls_terms(&mut pe[..len], sd, c, &mut terms);
            for q in 0..len {
                ps[q] = if terms.ok[q] > 0.0 { ps[q] } else { 0.0 };
            }
            ev.add_chunk_sums(terms.sums(&pe[..len]));
            if loss_only {
                lo = hi;
                continue;
            }
            if !reuse {
                outer_products(sd, &terms.wt, len, &mut outer);
            }
            // A warm evaluation sums the gradient's moments only (up to
            // `s^n_terms`); the matrix's (up to `s^(2 n_terms)`) are the level's
            // first evaluation's (see [`WarmStart`]).
            let moments = if reuse { n_terms } else { 2 * n_terms };
            // pw = s^p per point, p = 0..=moments (vectorized over points).
            let mut pw = [1f32; CHUNK];
            for p in 0..=moments {
                if p > 0 {
                    for q in 0..len {
                        pw[q] *= ps[q];
                    }
                }
                // Summed in lanes (as one serial f32 sum each, these 54 sums
                // per chunk were the tracker's hottest loop), the lanes added
                // up once after the last chunk.
                if !reuse {
                    for (o, acc) in outer.iter().zip(&mut h_lanes[p]) {
                        lanes::dot_into(&o[..len], &pw[..len], acc);
                    }
                }
                if p <= n_terms {
                    for (v, acc) in terms.we.iter().zip(&mut g_lanes[p]) {
                        lanes::dot_into(&v[..len], &pw[..len], acc);
                    }
                }
            }
            lo = hi;
        }
        for (p, acc) in h_lanes.iter().enumerate() {
            let hk = if p == 0 { &mut ev.h } else { &mut ev.hs[p - 1] };
            for (h, a) in hk.iter_mut().zip(acc) {
                *h = lanes::lanes_total(a);
            }
        }
        for (p, acc) in g_lanes.iter().enumerate() {
            let gk = if p == 0 { &mut ev.g } else { &mut ev.gs[p - 1] };
            for (g, a) in gk.iter_mut().zip(acc) {
                *g = lanes::lanes_total(a);
            }
        }
        if let Some(l) = warm_start {
            if reuse {
                (ev.h, ev.hs) = (l.h, l.hs);
            } else {
                (l.h, l.hs) = (ev.h, ev.hs);
            }
            l.valid = true;
        }
        ev
    }
}
