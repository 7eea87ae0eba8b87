//! Where a template ray lands in the current frame through a rolling shutter:
//! the readout fraction of a pixel, the readout path at it, and the small
//! rotation it turns the ray by.

use super::intrinsics::Intrinsics;
use super::residuals::sample_clamped;
use crate::image::GrayImage;
use crate::shutter::RowTime;

/// The readout fractions of pyramid level `level`'s pixels `(pu, pv)` into
/// `ps`: affine in the row, or from the level's table (`table`,
/// [`RowTime::level_table`]; a level without one, not reached, looks each
/// point up in `rows`).
#[inline(always)]
pub(super) fn row_times_into(
    rows: &RowTime,
    table: Option<&GrayImage>,
    level: usize,
    pu: &[f32],
    pv: &[f32],
    ps: &mut [f32],
) {
    match (rows, table) {
        (RowTime::Affine { a, b }, _) => {
            let k = (1u32 << level) as f32;
            let (a, b) = (a * k, a * 0.5 * (k - 1.0) + b);
            for (s, v) in ps.iter_mut().zip(pv) {
                *s = a * v + b;
            }
        }
        (_, Some(table)) => sample_clamped(table, pu, pv, ps),
        (rows, None) => {
            for ((s, u), v) in ps.iter_mut().zip(pu).zip(pv) {
                *s = rows.at(level, *u, *v);
            }
        }
    }
}

/// Where ray `r` (in the frame's mid-readout camera) lands at readout fraction
/// `s` of the readout path `path` (`[phi, psi, chi, xi]`): `pi(K exp(-a(s)) r)`,
/// `a(s) = s phi + s^2 psi + s^3 chi + s^4 xi`, the rotation to third order
/// ([`rotate_small`]). Inlined into the loops over points, which vectorize.
#[inline(always)]
pub(super) fn land_at(k: &Intrinsics, path: &[[f32; 3]; 4], s: f32, r: [f32; 3]) -> (f32, f32) {
    let b = path_at(path, s).map(|a| -a);
    let z = rotate_small(&b, &r);
    k.project(z[0], z[1], z[2])
}

/// `a(s) = s phi + s^2 psi + s^3 chi + s^4 xi` of the readout path `path`
/// (`[phi, psi, chi, xi]`), in Horner's form.
#[inline(always)]
pub(super) fn path_at(path: &[[f32; 3]; 4], s: f32) -> [f32; 3] {
    let [phi, psi, chi, xi] = path;
    std::array::from_fn(|i| (phi[i] + (psi[i] + (chi[i] + xi[i] * s) * s) * s) * s)
}

/// `exp(b) z` for a small rotation vector `b`, to third order:
/// `z + b x z + (b x (b x z)) / 2 + (b x (b x (b x z))) / 6` (error `|b|^4 / 24`).
#[inline(always)]
pub(super) fn rotate_small(b: &[f32; 3], z: &[f32; 3]) -> [f32; 3] {
    let cross = |a: &[f32; 3], c: &[f32; 3]| {
        [
            a[1] * c[2] - a[2] * c[1],
            a[2] * c[0] - a[0] * c[2],
            a[0] * c[1] - a[1] * c[0],
        ]
    };
    let b1 = cross(b, z);
    let b2 = cross(b, &b1);
    let b3 = cross(b, &b2);
    std::array::from_fn(|i| z[i] + b1[i] + 0.5 * b2[i] + b3[i] * (1.0 / 6.0))
}
