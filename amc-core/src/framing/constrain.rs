//! Keeping the view within the zoom: pull it toward the camera just enough.
//!
//! With `V(a) = V exp(a log(V^T R_cam))` (the geodesic from the smoothed view
//! `V` to the camera's orientation, `a` in `[0, 1]`), the shown view is
//! `V(a*)` for the least `a*` whose need is within the zoom, found by
//! bisection (need grows with the distance to the camera along the geodesic in
//! practice; the bisection keeps the answer feasible either way). At `a = 1`
//! the view is the camera's own, which its frame covers at zoom 1, so a
//! feasible view always exists for a zoom of at least 1 (up to `EDGE_PX`).

use super::coverage::{view_need, Border};
use crate::camera::CameraModel;
use crate::shutter::RollingProjector;
use crate::so3::{self, Rot};
use nalgebra::Matrix3;

/// Bisection steps (the pull is found to a 2^-12 share of the deviation).
const PULL_STEPS: usize = 12;

/// The view within `zoom` closest to `view` along the geodesic to `camera`,
/// for the averaged frames `window` (their orientations `R_hat_{0,i}`), and
/// its need. `view` itself when it needs no more than `zoom`; the camera when
/// even it needs more. `scratch` holds the rotations (reused).
#[allow(clippy::too_many_arguments)]
pub fn pull_view(
    src: &CameraModel,
    border: &Border,
    window: &[Rot],
    rows: &[RollingProjector],
    view: &Rot,
    camera: &Rot,
    zoom: f64,
    scratch: &mut Vec<Matrix3<f64>>,
) -> (Rot, f64) {
    let mut need_of = |v: &Rot| view_need(src, border, window, rows, v, scratch);
    let need = need_of(view);
    if need <= zoom {
        return (*view, need);
    }
    let need_cam = need_of(camera);
    if need_cam > zoom {
        return (*camera, need_cam);
    }
    let w = so3::log(&(view.transpose() * camera));
    let at = |a: f64| so3::renormalize(&(view * so3::exp(&(w * a))));
    let (mut lo, mut hi, mut need_hi) = (0.0, 1.0, need_cam);
    for _ in 0..PULL_STEPS {
        let mid = 0.5 * (lo + hi);
        let n = need_of(&at(mid));
        if n <= zoom {
            hi = mid;
            need_hi = n;
        } else {
            lo = mid;
        }
    }
    (at(hi), need_hi)
}
