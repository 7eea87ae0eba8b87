//! One continuous trajectory through the recent frames' readout paths.
//!
//! The tracker estimates each frame on its own: the mid-readout pose `R_j`
//! and the path `a_j(s)` across the readout ([`IntraFrame`]). With a rolling
//! shutter the pose at mid-readout is seen only by the middle rows; the
//! others see the camera earlier or later, and a frame's path has to be
//! fitted from its own rows. The value at the middle of a least-squares
//! polynomial fit is uncertain in proportion to the even terms it frees: a
//! quartic's has `1 + 5/4 + 81/64 = 3.5` times the variance of a plain mean
//! (Legendre: `sum_k (2k + 1) P_k(0)^2` over the even `k`), so a frame's pose
//! is 1.9 times less precise than a global shutter's, however well its rows
//! are aligned.
//!
//! The camera's orientation is one continuous curve, though, and consecutive
//! readouts (10-20 ms, every 16.7 ms) see most of it. So the recent frames'
//! paths are fitted together by one spline `R(t) = R_c exp(x(t))`, `x` a
//! quintic B-spline in time with knots every half frame period (finer than
//! the shake, coarse enough to smooth the noise), and the newest frame's pose
//! is read off it:
//! ```text
//! min  sum_j sum_m g_m | log(R_c^T R_j exp(a_j(s_m))) - x(t_j + tau (1 + e) s_m) - c(s_m) |^2
//! ```
//! (`s_m`, `g_m` Gauss-Legendre nodes and weights on the readout, so that a
//! frame's sum is its rows' integral; `R_c` the newest pose, a chart in which
//! a few degrees of shake are nearly flat.) Two nuisance terms keep the fit
//! from trusting what the tracker does not measure:
//! * `c(s) = sum_k c_k s^k`, the paths' common offset: alignment sees only a
//!   frame's readout motion *relative to its template's*, and the absolute
//!   value the tracker pins over blocks of frames ([`crate::tracker`]'s
//!   gauge) wanders between its corrections by more than the paths' own
//!   frame-to-frame error. Fitted freely per window, the offset leaves the
//!   paths' shapes to the fit and their level to continuity. It is common
//!   only while every frame held is in one gauge: when the tracker corrects
//!   its gauge (its block check, or a template regauged), the frames held are
//!   corrected alike ([`TrajectorySmoother::regauge`]).
//! * `e`, the readout's stretch ([`Stretch`]).
//!
//! The stabilizer uses the fitted pose where the tracker frees the path's
//! bend (`psi`: a fast pace, see [`crate::tracker::Tracker::estimates_bend`]);
//! at a slow pace it fits `phi` alone, an odd term that leaves the pose as
//! certain as a global shutter's, and there the fit only adds its own
//! assumptions.
//!
//! The fitted offset also serves the tracker: each new template is rectified
//! again with its path less the offset ([`TrajectorySmoother::path_offset`],
//! `Tracker::regauge_template`). A template's path off by `c` biases every
//! frame aligned to it by about `|a| |c| / 2` (the rotations do not
//! commute), a bias smooth in time and so kept by any spline. Corrected from
//! the start, the first frames' offset (while the tracker's gauge is
//! unknown) would stay, so it waits for [`STRETCH_AFTER`] fits.
//!
//! Only the pose is replaced: the newest frame's path, at the spline's end,
//! is pinned by its own rows alone, and there the spline's is noisier from
//! frame to frame than the tracker's.
//!
//! The fit is linear: a few dozen samples and about 30 unknowns per axis
//! with the same normal matrix for the three axes (the stretch, which
//! couples them, is eliminated by its Schur complement), solved by Cholesky
//! in fixed buffers; nothing is allocated per frame. A small penalty on the
//! coefficients' third differences keeps it solvable where the readout is so
//! short that whole knot spans see no row.
//!
//! The measurements behind these choices: see `docs/core-history.md#shutter-trajectory`.

use super::{IntraFrame, INTRA_TERMS};
use crate::so3::{self, Rot, Tangent};
use nalgebra::{SMatrix, SVector};
use std::collections::VecDeque;

/// Frames fitted together (the newest and the ones before it).
pub const TRAJECTORY_FRAMES: usize = 8;
/// Degree of the B-spline.
const DEGREE: usize = 5;
/// Knots per frame period.
const KNOTS_PER_FRAME: f64 = 2.0;
/// Most spline coefficients per axis (the knot spacing widens to fit).
const MAX_COEFFS: usize = 28;
/// Terms of the paths' common offset (`s, s^2, s^3, s^4`).
const OFFSET_TERMS: usize = INTRA_TERMS;
/// Most unknowns per axis.
const MAX_UNKNOWNS: usize = MAX_COEFFS + OFFSET_TERMS;
/// Weight of the penalties (third differences of the coefficients, and the
/// offset's size), relative to one frame's samples.
const SMOOTHING: f64 = 1e-6;
/// Fewest frames (with weight) for a fit; before that the tracker's own
/// estimates stand.
const MIN_FRAMES: usize = 3;
/// Fits before the stretch is estimated: the tracker holds its first
/// template until its gauge is known, and the paths before are far off.
const STRETCH_AFTER: usize = 2 * TRAJECTORY_FRAMES;
/// Per-fit decay of the pooled stretch (a memory of about 50 frames).
const STRETCH_DECAY: f64 = 0.98;
/// Largest stretch used: a readout off by more than a quarter is not this
/// fit's to correct.
const MAX_STRETCH: f64 = 0.25;

/// Gauss-Legendre nodes (readout fractions in `[-1/2, 1/2]`) and weights
/// (summing to 1) of six points: exact for polynomials up to degree 11.
const NODES: [(f64, f64); 6] = [
    (-0.466_234_757_101_576, 0.085_662_246_189_585),
    (-0.330_604_693_233_132, 0.180_380_786_524_069),
    (-0.119_309_593_041_598, 0.233_956_967_286_346),
    (0.119_309_593_041_598, 0.233_956_967_286_346),
    (0.330_604_693_233_132, 0.180_380_786_524_069),
    (0.466_234_757_101_576, 0.085_662_246_189_585),
];

/// What the readout given is off by, as the paths show it.
///
/// The tracker measures each frame's path against its rows (readout
/// fractions), whatever the readout; the fit places row `s` at time
/// `t + readout s`. A readout off by a share `e` misplaces the samples in
/// time, by far more than the poses' error at fast motion. So `e` is a
/// parameter of every fit (a sample read at `s` is the rotation at
/// `t + readout (1 + e) s`, to first order `x(t + readout s) + e s a'(s)`),
/// and its estimates are pooled over the recent fits, each weighted by its
/// information (a fast pace pins it, a slow one barely). The pooled value is
/// the one used, and the next fit places its samples with it, so the
/// first-order model only has to find what is left (see `docs/core-history.md#shutter-stretch`).
#[derive(Clone, Copy, Debug, Default)]
struct Stretch {
    /// Decayed sums of information-weighted estimates and of information.
    sum: f64,
    info: f64,
}

impl Stretch {
    fn add(&mut self, estimate: f64, info: f64) {
        self.sum = STRETCH_DECAY * self.sum + info * estimate;
        self.info = STRETCH_DECAY * self.info + info;
    }

    fn value(&self) -> f64 {
        if self.info > 0.0 {
            (self.sum / self.info).clamp(-MAX_STRETCH, MAX_STRETCH)
        } else {
            0.0
        }
    }
}

/// One frame as the tracker saw it.
#[derive(Clone, Copy, Debug)]
struct Observed {
    t: f64,
    pose: Rot,
    intra: IntraFrame,
    weight: f64,
    /// Its rotations at the [`NODES`], `R_j exp(a_j(s_m))` (each fit
    /// takes them into its own chart).
    at_nodes: [Rot; NODES.len()],
}

/// Fits the recent frames' poses and readout paths with one spline and
/// returns the newest frame's pose on it ([`TrajectorySmoother::push`]).
/// Memory: [`TRAJECTORY_FRAMES`] frames and fixed-size buffers.
pub struct TrajectorySmoother {
    /// The readout given, seconds.
    readout_s: f64,
    frames: VecDeque<Observed>,
    /// Normal matrix, shared by the three axes.
    normal: Box<SMatrix<f64, MAX_UNKNOWNS, MAX_UNKNOWNS>>,
    /// Right-hand sides, one column per axis; solved in place.
    rhs: Box<SMatrix<f64, MAX_UNKNOWNS, 3>>,
    /// The stretch's columns of the normal equations; solved in place.
    slope: Box<SMatrix<f64, MAX_UNKNOWNS, 3>>,
    stretch: Stretch,
    /// Fits made so far.
    fits: usize,
    /// The last fit's common offset of the paths.
    offset: IntraFrame,
}

impl TrajectorySmoother {
    /// An empty smoother for frames read out in `readout_s` seconds (a
    /// readout up to a quarter off is corrected, see [`Stretch`]).
    pub fn new(readout_s: f64) -> Self {
        Self {
            readout_s,
            frames: VecDeque::with_capacity(TRAJECTORY_FRAMES),
            normal: Box::new(SMatrix::zeros()),
            rhs: Box::new(SMatrix::zeros()),
            slope: Box::new(SMatrix::zeros()),
            stretch: Stretch::default(),
            fits: 0,
            offset: IntraFrame::ZERO,
        }
    }

    /// The paths' common offset at the last fit (the tracker's gauge error, in
    /// the newest frame's camera axes), once the fit has seen enough frames to
    /// trust it (the tracker's first paths wait for its gauge; see
    /// `docs/core-history.md#shutter-path-offset`).
    pub fn path_offset(&self) -> Option<IntraFrame> {
        (self.fits > STRETCH_AFTER).then_some(self.offset)
    }

    /// The paths' common offset at the last fit, from the first fit on: what
    /// [`TrajectorySmoother::path_offset`] gives once trusted, but also while
    /// the tracker's gauge is still the first frame's (every path then has
    /// the same offset, minus the first frame's path, and a few frames pin it;
    /// see `docs/core-history.md#shutter-fitted-offset`). `None` before the first fit.
    pub fn fitted_offset(&self) -> Option<IntraFrame> {
        (self.fits > 0).then_some(self.offset)
    }

    /// The tracker's gauge moved by `correction` (every path it reports from
    /// now on is lower by it): the frames held are corrected alike, so that
    /// the window keeps one common offset.
    pub fn regauge(&mut self, correction: &IntraFrame) {
        if correction.is_zero() {
            return;
        }
        for f in self.frames.iter_mut() {
            f.intra = f.intra.plus(correction, -1.0);
            let (pose, intra) = (f.pose, f.intra);
            f.at_nodes = NODES.map(|(s, _)| pose * intra.rotation_at(s));
        }
    }

    /// The readout the paths have shown so far, as a multiple of the one
    /// given (1 until they show it).
    pub fn readout_scale(&self) -> f64 {
        1.0 + self.stretch.value()
    }

    /// Adds frame `t` (seconds; after the last one) with the tracker's pose
    /// and readout path for it, and returns its pose on the spline through
    /// the recent frames. `weight` is the frame's say in the fit (0: a lost
    /// frame, its estimate a guess); with too few frames, a weightless newest
    /// frame or no readout, the tracker's own pose is returned.
    pub fn push(&mut self, t: f64, pose: Rot, intra: IntraFrame, weight: f64) -> Rot {
        if self.frames.len() == TRAJECTORY_FRAMES {
            self.frames.pop_front();
        }
        self.frames.push_back(Observed {
            t,
            pose,
            intra,
            weight,
            at_nodes: NODES.map(|(s, _)| pose * intra.rotation_at(s)),
        });
        let weighted = self.frames.iter().filter(|f| f.weight > 0.0).count();
        if weight <= 0.0 || weighted < MIN_FRAMES || !(self.readout_s > 0.0) {
            return pose;
        }
        self.fit().unwrap_or(pose)
    }

    /// The fit of the frames held, evaluated at the newest one.
    fn fit(&mut self) -> Option<Rot> {
        // The samples are placed with the stretch found so far, and the fit
        // estimates what is left of it (a first-order model; see
        // `docs/core-history.md#shutter-stretch-steps`).
        let placed = 1.0 + self.stretch.value();
        let readout_s = self.readout_s * placed;
        let newest = *self.frames.back()?;
        let oldest = self.frames.front()?;
        let start = oldest.t - 0.5 * readout_s;
        let span = newest.t + 0.5 * readout_s - start;
        let period = self.median_period()?;
        // Knots every half period, wider where that would not fit the buffers.
        let spacing = (period / KNOTS_PER_FRAME).max(span / (MAX_COEFFS - DEGREE - 1) as f64);
        let coeffs = ((span / spacing).floor() as usize + DEGREE + 1).min(MAX_COEFFS);
        let unknowns = coeffs + OFFSET_TERMS;
        let chart = newest.pose.inverse();

        // Per axis the unknowns are the spline's coefficients and the
        // offset's terms; the stretch `e` couples the axes through its
        // regressor `q = s a'(s)`.
        self.normal.fill(0.0);
        self.rhs.fill(0.0);
        self.slope.fill(0.0);
        let (mut qq, mut qy) = (0.0, 0.0);
        for frame in &self.frames {
            if frame.weight <= 0.0 {
                continue;
            }
            let [phi, psi, chi, xi] = frame.intra.terms();
            for (&(s, g), at) in NODES.iter().zip(&frame.at_nodes) {
                let y = so3::log(&(chart * at));
                let q = (phi + (psi * 2.0 + (chi * 3.0 + xi * (4.0 * s)) * s) * s) * s;
                let (first, basis) = bspline_basis((frame.t + readout_s * s - start) / spacing);
                // This sample's row: the spline's basis at `first..`, then
                // `s^k` at `coeffs..`; its outer products in blocks.
                let first = first.min(coeffs - DEGREE - 1);
                let b = SVector::<f64, { DEGREE + 1 }>::from(basis);
                let p = SVector::<f64, OFFSET_TERMS>::from_fn(|k, _| s.powi(k as i32 + 1));
                let w = frame.weight * g;
                let (wb, wp) = (b * w, p * w);
                let normal = &mut *self.normal;
                let cross = wb * p.transpose();
                let mut view =
                    normal.fixed_view_mut::<{ DEGREE + 1 }, { DEGREE + 1 }>(first, first);
                view += wb * b.transpose();
                let mut view = normal.fixed_view_mut::<{ DEGREE + 1 }, OFFSET_TERMS>(first, coeffs);
                view += cross;
                let mut view = normal.fixed_view_mut::<OFFSET_TERMS, { DEGREE + 1 }>(coeffs, first);
                view += cross.transpose();
                let mut view = normal.fixed_view_mut::<OFFSET_TERMS, OFFSET_TERMS>(coeffs, coeffs);
                view += wp * p.transpose();
                for (columns, v) in [(&mut *self.rhs, y), (&mut *self.slope, q)] {
                    let mut view = columns.fixed_view_mut::<{ DEGREE + 1 }, 3>(first, 0);
                    view += wb * v.transpose();
                    let mut view = columns.fixed_view_mut::<OFFSET_TERMS, 3>(coeffs, 0);
                    view += wp * v.transpose();
                }
                qq += w * q.norm_squared();
                qy += w * q.dot(&y);
            }
        }
        // Third differences of the coefficients: (1, -3, 3, -1).
        const DIFF: [f64; 4] = [1.0, -3.0, 3.0, -1.0];
        for i in 0..coeffs.saturating_sub(3) {
            for (a, &da) in DIFF.iter().enumerate() {
                for (b, &db) in DIFF.iter().enumerate() {
                    self.normal[(i + a, i + b)] += SMOOTHING * da * db;
                }
            }
        }
        for i in coeffs..unknowns {
            self.normal[(i, i)] += SMOOTHING;
        }
        // The unused unknowns: an identity block, so the fixed-size
        // factorisation solves them to zero.
        for i in unknowns..MAX_UNKNOWNS {
            self.normal[(i, i)] = 1.0;
        }
        let chol = nalgebra::Cholesky::new(*self.normal)?;
        // The stretch's Schur complement: with `x = x0 - e z` (`N x0 = b`,
        // `N z = d`), `(qq - d.z) e = qy - d.x0`.
        let d = *self.slope;
        chol.solve_mut(&mut *self.rhs);
        chol.solve_mut(&mut *self.slope);
        let (mut dz, mut dx0) = (0.0, 0.0);
        for axis in 0..3 {
            dz += d.column(axis).dot(&self.slope.column(axis));
            dx0 += d.column(axis).dot(&self.rhs.column(axis));
        }
        let info = qq - dz;
        self.fits += 1;
        if info > 0.0 && info.is_finite() && self.fits > STRETCH_AFTER {
            let left = (qy - dx0) / info;
            self.stretch.add(placed * (1.0 + left) - 1.0, info);
        }
        // What the pooled stretch leaves of the placement's.
        let e = (1.0 + self.stretch.value()) / placed - 1.0;

        self.offset = IntraFrame::from_terms(std::array::from_fn(|k| {
            Tangent::from_fn(|axis, _| {
                self.rhs[(coeffs + k, axis)] - e * self.slope[(coeffs + k, axis)]
            })
        }));
        // The pose: `x(t_newest)`, with `x = x0 - e z`.
        let (first, basis) = bspline_basis((newest.t - start) / spacing);
        let first = first.min(coeffs - DEGREE - 1);
        let mut x = Tangent::zeros();
        for (a, &ba) in basis.iter().enumerate() {
            let i = first + a;
            for axis in 0..3 {
                x[axis] += ba * (self.rhs[(i, axis)] - e * self.slope[(i, axis)]);
            }
        }
        let pose = newest.pose * so3::exp(&x);
        pose.matrix()
            .iter()
            .all(|v| v.is_finite())
            .then(|| so3::renormalize(&pose))
    }

    /// The median time between the frames held, seconds.
    fn median_period(&self) -> Option<f64> {
        let mut gaps = [0.0; TRAJECTORY_FRAMES];
        let n = self.frames.len().checked_sub(1)?;
        for (g, (a, b)) in gaps
            .iter_mut()
            .zip(self.frames.iter().zip(self.frames.iter().skip(1)))
        {
            *g = b.t - a.t;
        }
        let gaps = &mut gaps[..n];
        gaps.sort_by(f64::total_cmp);
        let median = *gaps.get(n / 2)?;
        (median > 0.0 && median.is_finite()).then_some(median)
    }
}

/// The uniform B-spline basis of degree [`DEGREE`] at `u` (in knot spacings
/// from the first knot; clamped to `>= 0`): the index of the first
/// coefficient that is non-zero there and the `DEGREE + 1` values from it on.
///
/// Cox-de Boor on unit knots: with `M_0 = 1` on `[0, 1)` and
/// `M_d(x) = (x M_{d-1}(x) + (d + 1 - x) M_{d-1}(x - 1)) / d`, the values
/// `M_d(f + r)`, `r = 0..=d`, at the fractional part `f` belong to the
/// functions starting `r` knots to the left.
fn bspline_basis(u: f64) -> (usize, [f64; DEGREE + 1]) {
    let u = u.max(0.0);
    let knot = u.floor();
    let f = u - knot;
    let mut v = [0.0; DEGREE + 1];
    v[0] = 1.0;
    for d in 1..=DEGREE {
        let df = d as f64;
        for r in (0..=d).rev() {
            let rf = r as f64;
            let own = if r < d { (f + rf) * v[r] } else { 0.0 };
            let left = if r > 0 {
                (df + 1.0 - f - rf) * v[r - 1]
            } else {
                0.0
            };
            v[r] = (own + left) / df;
        }
    }
    // Value `r` belongs to the function starting at knot `knot - r`, whose
    // coefficient is `knot - r + DEGREE`: reversed, the index rises.
    v.reverse();
    (knot as usize, v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix4, Vector4};

    /// 12-20 Hz shake on three axes, about 200 deg/s RMS.
    fn shake(t: f64) -> Rot {
        let w = |f: f64, p: f64| (2.0 * std::f64::consts::PI * f * t + p).sin();
        so3::exp(&Tangent::new(
            0.03 * w(13.0, 0.2) + 0.01 * w(19.0, 1.0),
            0.025 * w(15.0, 2.0) + 0.012 * w(17.5, 0.4),
            0.01 * w(12.5, 0.7),
        ))
    }

    /// The quartic path through `rot(s)` (the rotation at readout fraction
    /// `s`) at `s = -1/2, -1/4, 1/4, 1/2`, relative to `pose = rot(0)`.
    fn quartic_through(pose: &Rot, rot: impl Fn(f64) -> Rot) -> IntraFrame {
        const S: [f64; 4] = [-0.5, -0.25, 0.25, 0.5];
        let v = Matrix4::from_fn(|i, k| S[i].powi(k as i32 + 1));
        let inv = v.try_inverse().unwrap();
        let a: Vec<Tangent> = S
            .iter()
            .map(|&s| so3::log(&(pose.inverse() * rot(s))))
            .collect();
        IntraFrame::from_terms(std::array::from_fn(|k| {
            Tangent::from_fn(|axis, _| (inv.row(k) * Vector4::from_fn(|i, _| a[i][axis]))[(0, 0)])
        }))
    }

    #[test]
    fn basis_is_a_partition_of_unity() {
        for &u in &[0.0, 0.3, 1.7, 5.999, 12.25] {
            let (first, v) = bspline_basis(u);
            assert_eq!(first, u.floor() as usize);
            assert!((v.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{u}: {v:?}");
            assert!(v.iter().all(|&b| b >= 0.0));
        }
        // The quintic cardinal B-spline at its knots: 1, 26, 66, 26, 1 (/120).
        let (_, v) = bspline_basis(7.0);
        let expect = [1.0, 26.0, 66.0, 26.0, 1.0, 0.0].map(|x| x / 120.0);
        for (a, b) in v.iter().zip(expect) {
            assert!((a - b).abs() < 1e-12, "{v:?}");
        }
    }

    /// Exact poses and paths come back as they were; and so they do with the
    /// paths' common offset (the tracker's gauge error) and a readout given
    /// 5% long or 20% short, both of which the fit finds.
    #[test]
    fn exact_poses_are_kept_through_offsets_and_a_wrong_readout() {
        let (fps, readout) = (60.0, 0.015);
        let offset = IntraFrame {
            phi: Tangent::new(0.002, -0.001, 0.0015),
            psi: Tangent::new(-0.001, 0.0005, 0.0),
            ..IntraFrame::ZERO
        };
        for (given, offset) in [
            (1.0, IntraFrame::ZERO),
            (1.0, offset),
            (1.05, IntraFrame::ZERO),
            (0.8, offset),
        ] {
            let mut smoother = TrajectorySmoother::new(given * readout);
            let mut worst = 0.0f64;
            for j in 0..240 {
                let t = j as f64 / fps;
                let pose = shake(t);
                let intra = quartic_through(&pose, |s| shake(t + readout * s)).plus(&offset, 1.0);
                let p = smoother.push(t, pose, intra, 1.0);
                if j >= 60 {
                    worst = worst.max(so3::angle_between(&p, &pose).to_degrees());
                }
            }
            // 0.5 px of a 320 px frame of 90 degrees is 0.14 deg; this is 1/50 px.
            assert!(
                worst < 2e-3,
                "readout x{given}, offset {offset:?}: {worst} deg"
            );
            let found = smoother.path_offset().expect("enough fits");
            let off_err = [-0.5, -0.25, 0.25, 0.5]
                .iter()
                .map(|&s| (found.at(s) - offset.at(s)).norm())
                .fold(0.0, f64::max)
                .to_degrees();
            // The offset over the readout, within 0.002 deg (measured
            // 0.0017-0.0022; it was 0 or 0.11 deg at the readout's ends).
            assert!(
                off_err < 4e-3,
                "readout x{given}: offset off by {off_err} deg"
            );
            let scale = smoother.readout_scale() * given;
            assert!(
                (scale - 1.0).abs() < 0.01,
                "readout x{given}: found x{scale}"
            );
        }
    }

    /// A gauge that changes every 5 frames (as the tracker corrects it): told
    /// of each change ([`TrajectorySmoother::regauge`]), the fit keeps the
    /// exact poses and finds the gauge of the newest frames; not told, its
    /// windows mix two offsets and the poses drift off (see
    /// `docs/core-history.md#shutter-regauge-test`).
    #[test]
    fn a_gauge_corrected_in_steps_is_followed() {
        let (fps, readout) = (60.0, 0.015);
        let step = IntraFrame {
            phi: Tangent::new(0.0015, -0.001, 0.0008),
            psi: Tangent::new(-0.0008, 0.0004, 0.0),
            ..IntraFrame::ZERO
        };
        let mut worst = [0.0f64; 2];
        for (told, worst) in [true, false].into_iter().zip(&mut worst) {
            let mut smoother = TrajectorySmoother::new(readout);
            let mut offset = IntraFrame::ZERO;
            for j in 0..120 {
                if j % 5 == 0 {
                    // The gauge is corrected by `c`, back and forth: later
                    // paths are lower by it.
                    let c = step.plus(&step, if j % 10 == 0 { -2.0 } else { 0.0 });
                    offset = offset.plus(&c, -1.0);
                    if told {
                        smoother.regauge(&c);
                    }
                }
                let t = j as f64 / fps;
                let pose = shake(t);
                let intra = quartic_through(&pose, |s| shake(t + readout * s)).plus(&offset, 1.0);
                let p = smoother.push(t, pose, intra, 1.0);
                if j >= 30 {
                    *worst = worst.max(so3::angle_between(&p, &pose).to_degrees());
                }
            }
            if told {
                let found = smoother.fitted_offset().expect("fitted");
                let off_err = [-0.5, -0.25, 0.25, 0.5]
                    .iter()
                    .map(|&s| (found.at(s) - offset.at(s)).norm())
                    .fold(0.0, f64::max)
                    .to_degrees();
                assert!(off_err < 4e-3, "offset off by {off_err} deg");
            }
        }
        let [told, not_told] = worst;
        assert!(told < 2e-3, "told: {told} deg");
        assert!(not_told > 2.0 * told, "not told: {not_told} deg vs {told}");
    }

    /// A tiny deterministic normal generator (xorshift and Box-Muller).
    struct Noise(u64);
    impl Noise {
        fn normal(&mut self) -> f64 {
            let mut uniform = || {
                self.0 ^= self.0 << 13;
                self.0 ^= self.0 >> 7;
                self.0 ^= self.0 << 17;
                (self.0 >> 11) as f64 / (1u64 << 53) as f64
            };
            let (u, v) = (uniform().max(1e-300), uniform());
            (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
        }
    }

    /// Frames measured as the tracker does, each by its own rows (a noisy
    /// rotation per row, fitted with a quartic path): the spline's poses
    /// differ from frame to frame by less error than the frames' own.
    #[test]
    fn the_trajectory_beats_the_frames_on_their_own() {
        let (fps, readout, rows, sigma) = (60.0, 0.015, 48, 0.02f64.to_radians());
        let mut noise = Noise(0x9e37_79b9_7f4a_7c15);
        let mut smoother = TrajectorySmoother::new(readout);
        let (mut raw, mut smoothed) = (Vec::new(), Vec::new());
        let mut last: Option<(Rot, Rot, Rot)> = None;
        for j in 0..300 {
            let t = j as f64 / fps;
            // Each row sees the rotation at its time, with noise; the frame
            // fits a rotation and a quartic path to its rows (linear least
            // squares in the frame's chart, about its true pose).
            let truth = shake(t);
            let mut normal = SMatrix::<f64, 5, 5>::zeros();
            let mut rhs = SMatrix::<f64, 5, 3>::zeros();
            for r in 0..rows {
                let s = (r as f64 + 0.5) / rows as f64 - 0.5;
                let seen = so3::log(&(truth.inverse() * shake(t + readout * s)))
                    + Tangent::from_fn(|_, _| sigma * noise.normal());
                let basis = SMatrix::<f64, 5, 1>::from_fn(|k, _| s.powi(k as i32));
                normal += basis * basis.transpose();
                rhs += basis * seen.transpose();
            }
            let fit = normal.try_inverse().unwrap() * rhs;
            let poly = |s: f64| {
                truth
                    * so3::exp(&Tangent::from_fn(|axis, _| {
                        (0..5).map(|k| fit[(k, axis)] * s.powi(k as i32)).sum()
                    }))
            };
            let pose = poly(0.0);
            let intra = quartic_through(&pose, poly);
            let p = smoother.push(t, pose, intra, 1.0);
            if let Some((truth0, pose0, p0)) = last {
                if j > 30 {
                    let d_true = truth0.inverse() * truth;
                    raw.push(so3::angle_between(&d_true, &(pose0.inverse() * pose)));
                    smoothed.push(so3::angle_between(&d_true, &(p0.inverse() * p)));
                }
            }
            last = Some((truth, pose, p));
        }
        let rms = |v: &[f64]| (v.iter().map(|e| e * e).sum::<f64>() / v.len() as f64).sqrt();
        let (raw, smoothed) = (rms(&raw), rms(&smoothed));
        eprintln!("per-frame error RMS: frames alone {raw:.3e}, trajectory {smoothed:.3e} rad");
        assert!(smoothed < 0.85 * raw, "{smoothed} vs {raw}");
    }
}
