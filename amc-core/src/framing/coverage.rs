//! The least zoom at which every output pixel is covered by some averaged frame.
//!
//! A point `q` of the output's normalized image plane (the ray `(q, 1)` of the
//! unzoomed output) is covered by frame `i` when `project_i(M_i (q, 1))` lands
//! at least [`EDGE_PX`] inside frame `i` (`M_i = R_hat_{0,i}^T R^view`). At
//! zoom `z` the output's border is the unzoomed border scaled by `s = 1 / z`
//! about the centre. For each border point `b_k`, the reach of frame `i` is the
//! largest `t <= 1` such that `t b_k` is covered (bisection from the centre;
//! 0 when the centre itself is not covered); the window reaches
//! `s_k = max_i t_{k,i}` along that ray, and the need is `1 / min_k s_k`.
//!
//! This is exact when every frame's covered region is star-shaped about the
//! output's centre (convex for pinhole sources, near so for real lenses) and
//! the border is sampled densely enough: points are spread every
//! [`BORDER_STEP_PX`] output pixels along each edge, corners included, so the
//! union's boundary cannot cut in between two of them by more than a fraction
//! of a pixel at the output's scale.

use crate::camera::CameraModel;
use crate::shutter::RollingProjector;
use crate::so3::Rot;
use nalgebra::{Matrix3, Vector2, Vector3};

/// How far inside a source frame a covered point must land, source pixels:
/// the chroma planes of 4:2:0 frames end half a luma pixel before the luma
/// plane (chroma sample `c` sits at luma `2 c + 0.5`), plus a quarter pixel for
/// the renderer's interpolated lens grid and single-precision maps.
pub const EDGE_PX: f64 = 0.75;

/// Spacing of the border points, output pixels.
pub const BORDER_STEP_PX: usize = 8;

/// Most points per edge (large outputs are sampled more sparsely).
const MAX_POINTS_PER_EDGE: usize = 96;

/// Bisection steps along a ray (a 2^-14 share of the half-diagonal).
const REACH_STEPS: usize = 14;
/// The fixed-point tolerance of a coverage test's rolling-shutter projection
/// (pixels; see [`RollingProjector::project_within`]): a point is tested
/// against a margin of [`EDGE_PX`], so a hundredth of a pixel is exact
/// enough, and the binary searches' projections (most of a rolling-shutter
/// run's, from the mid-readout guess) take a step or two fewer than at the
/// renderer's tolerance.
const COVERAGE_TOLERANCE_PX: f64 = 0.01;

/// The need reported when no zoom shows every pixel (the centre uncovered).
pub const NO_ZOOM_SUFFICES: f64 = 1e3;

/// Points along an output camera's border, in its normalized image plane at zoom 1.
#[derive(Clone, Debug, Default)]
pub struct Border {
    points: Vec<Vector2<f64>>,
}

impl Border {
    /// The border of `out` (a pinhole): its outermost pixel centres.
    pub fn new(out: &CameraModel) -> Self {
        let (w, h) = (
            out.width.max(2) as f64 - 1.0,
            out.height.max(2) as f64 - 1.0,
        );
        let per_edge = |len: usize| (len / BORDER_STEP_PX).clamp(2, MAX_POINTS_PER_EDGE);
        let (nx, ny) = (per_edge(out.width), per_edge(out.height));
        let mut pixels = Vec::with_capacity(2 * (nx + ny));
        for k in 0..nx {
            let u = w * k as f64 / nx as f64;
            pixels.push((u, 0.0));
            pixels.push((w - u, h));
        }
        for k in 0..ny {
            let v = h * k as f64 / ny as f64;
            pixels.push((w, v));
            pixels.push((0.0, h - v));
        }
        let points = pixels
            .into_iter()
            .map(|(u, v)| {
                let yn = (v - out.cy) / out.fy;
                Vector2::new((u - out.cx - out.skew * yn) / out.fx, yn)
            })
            .collect();
        Self { points }
    }

    /// The border points.
    pub fn points(&self) -> &[Vector2<f64>] {
        &self.points
    }
}

/// `Z^-1 = diag(1/z, 1/z, 1)`: the unzoomed output ray of a zoomed output's pixel.
pub fn zoom_matrix(zoom: f64) -> Matrix3<f64> {
    let s = 1.0 / zoom;
    Matrix3::new(s, 0.0, 0.0, 0.0, s, 0.0, 0.0, 0.0, 1.0)
}

/// Whether output point `q` (normalized, unzoomed) lands inside `src` through `m`.
/// `row`: through a rolling shutter, a nearby point's landing row (a start
/// for the fixed point, which saves steps), updated to this point's.
#[inline]
fn covers(
    src: &CameraModel,
    m: &Matrix3<f64>,
    rows: &RollingProjector,
    q: &Vector2<f64>,
    row: &mut Option<f64>,
) -> bool {
    let ray = m * Vector3::new(q.x, q.y, 1.0);
    match rows.project_within(src, &ray, *row, COVERAGE_TOLERANCE_PX) {
        Some(p) => {
            *row = Some(p.y).filter(|y| y.is_finite());
            let (xmax, ymax) = (src.width as f64 - 1.0, src.height as f64 - 1.0);
            p.x >= EDGE_PX && p.y >= EDGE_PX && p.x <= xmax - EDGE_PX && p.y <= ymax - EDGE_PX
        }
        None => false,
    }
}

/// How far out along `b` (from the centre) `m` keeps points inside `src`, in `[0, 1]`.
fn reach(
    src: &CameraModel,
    m: &Matrix3<f64>,
    rows: &RollingProjector,
    b: &Vector2<f64>,
    at_least: f64,
) -> f64 {
    // The search's points lie on one line: each starts from the last's row.
    let mut row = None;
    if covers(src, m, rows, b, &mut row) {
        return 1.0;
    }
    // Only a reach beyond what another frame already gives can matter.
    if !covers(src, m, rows, &(b * at_least.max(1e-9)), &mut row) {
        return 0.0;
    }
    let (mut lo, mut hi) = (at_least, 1.0);
    for _ in 0..REACH_STEPS {
        let mid = 0.5 * (lo + hi);
        if covers(src, m, rows, &(b * mid), &mut row) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// [`needed_zoom`] of the view `view` for averaged frames of orientations
/// `window` (`R_hat_{0,i}`): the maps `M_i = R_hat_{0,i}^T view`, built in
/// `scratch` (reused).
pub fn view_need(
    src: &CameraModel,
    border: &Border,
    window: &[Rot],
    rows: &[RollingProjector],
    view: &Rot,
    scratch: &mut Vec<Matrix3<f64>>,
) -> f64 {
    scratch.clear();
    scratch.extend(
        window
            .iter()
            .map(|r| r.matrix().transpose() * view.matrix()),
    );
    needed_zoom(src, border, scratch, rows)
}

/// The least zoom, at least 1, at which every pixel of the output whose
/// border is `border` is covered by at least one of the frames mapped by
/// `rotations` (`M_i`, output ray -> source ray, without the zoom) into
/// `src`. [`NO_ZOOM_SUFFICES`] when the output's centre is not covered.
pub fn needed_zoom(
    src: &CameraModel,
    border: &Border,
    rotations: &[Matrix3<f64>],
    rows: &[RollingProjector],
) -> f64 {
    let global = RollingProjector::default();
    let rows_of = |i: usize| rows.get(i).unwrap_or(&global);
    let centre = Vector2::zeros();
    if !rotations
        .iter()
        .enumerate()
        .any(|(i, m)| covers(src, m, rows_of(i), &centre, &mut None))
    {
        return NO_ZOOM_SUFFICES;
    }
    let mut smallest = 1.0f64;
    for b in border.points() {
        let mut best = 0.0f64;
        for (i, m) in rotations.iter().enumerate() {
            best = best.max(reach(src, m, rows_of(i), b, best));
            if best >= 1.0 {
                break;
            }
        }
        smallest = smallest.min(best);
    }
    if smallest <= 1.0 / NO_ZOOM_SUFFICES {
        NO_ZOOM_SUFFICES
    } else {
        1.0 / smallest
    }
}
