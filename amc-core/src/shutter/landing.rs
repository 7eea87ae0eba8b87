//! A frame's rolling-shutter landing map, tabulated once per frame.
//!
//! Through a rolling shutter a ray lands where the fixed point of
//! [`RollingProjector::project_within`] puts it: two to three projections
//! through the lens per ray, each with an `atan2` for a fisheye. A frame that
//! is averaged into several outputs is projected again for every one of them,
//! along other rays each time. But where a ray lands depends only on where it
//! would land at mid-readout: for the mid-readout pixel `p0 = pi(z)` the
//! landing pixel is
//! ```text
//! p = p0 + D(p0),    D(p0) = project_rolling(pi^-1(p0)) - p0
//! ```
//! and the displacement `D` is a smooth field over the frame (the readout
//! rotation `exp(-a(s))` is small and varies slowly with the row). So
//! [`LandingGrid`] samples `D` once per frame on a grid of mid-readout pixels
//! and interpolates it (a cubic); each output's rays then need one plain
//! projection and a lookup. Rays whose mid-readout pixel falls outside the grid,
//! or in a cell with a node the lens cannot see, get `None` and are projected
//! exactly by the caller.

use super::project::RollingProjector;
use crate::camera::CameraModel;
use nalgebra::Vector2;

/// Grid spacing of a [`LandingGrid`], source pixels. Between the nodes the
/// displacement is interpolated with a Catmull-Rom cubic, whose error falls
/// with the fourth power of the spacing: 16 px cells stay under the render
/// grid's own 0.005 px (see the tests), at about as many nodes per frame as
/// one map of the frame has (see `docs/core-history.md#shutter-landing-grid-step`).
pub const LANDING_GRID_STEP: f64 = 16.0;

/// The fixed-point tolerance of a node's landing (pixels): a node is computed
/// once per frame, so it can afford the library's finest.
const NODE_TOLERANCE_PX: f64 = super::FIXED_POINT_TOLERANCE_PX;

/// The displacement `D(p0)` from a frame's mid-readout pixels to its
/// rolling-shutter landing pixels, on a grid over the frame and a margin
/// around it (see the module's docs). Empty for a global shutter.
#[derive(Clone, Debug, Default)]
pub struct LandingGrid {
    /// Position of node `(0, 0)` (pixels; the grid starts outside the frame).
    origin: Vector2<f64>,
    /// Nodes per row and per column.
    width: usize,
    height: usize,
    /// `D` at the nodes, row-major; NaN where the node's ray is not seen.
    nodes: Vec<[f64; 2]>,
}

impl LandingGrid {
    /// True when nothing is tabulated (a global shutter, or not set yet).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Empties the grid, keeping its memory.
    pub fn clear(&mut self) {
        self.nodes.clear();
    }

    /// The grid's first node and its size in nodes: the frame and a margin
    /// as wide as a ray can move during the readout (the largest readout
    /// rotation times the lens's scale in px per radian, which a fisheye's
    /// only loses outward), so that no mid-readout pixel further out can land
    /// in the frame, and the ring of nodes the cubic reads around a cell.
    fn layout(rows: &RollingProjector, cam: &CameraModel) -> (Vector2<f64>, usize, usize) {
        let step = LANDING_GRID_STEP;
        let k = cam.k_matrix();
        let reach = rows.max_angle() * k[(0, 0)].max(k[(1, 1)]) * 1.25;
        let margin = (reach / step).ceil() * step + 2.0 * step;
        let (w, h) = (cam.width as f64 - 1.0, cam.height as f64 - 1.0);
        let nodes = |size: f64| ((size + 2.0 * margin) / step).ceil() as usize + 1;
        (Vector2::new(-margin, -margin), nodes(w), nodes(h))
    }

    /// Tabulates the landing map of a frame seen through `cam` whose rows
    /// turn by `rows` (empty for a global shutter: the grid is then empty).
    /// The grid covers the frame and the margin a ray can move by during the
    /// readout. Reuses the grid's memory.
    pub fn set(&mut self, rows: &RollingProjector, cam: &CameraModel) {
        self.nodes.clear();
        if rows.is_global() {
            return;
        }
        let step = LANDING_GRID_STEP;
        (self.origin, self.width, self.height) = Self::layout(rows, cam);
        self.nodes.reserve(self.width * self.height);
        for gy in 0..self.height {
            // Each node starts from its left neighbour's landing row.
            let mut guess = None;
            for gx in 0..self.width {
                let p0 = self.origin + Vector2::new(gx as f64, gy as f64) * step;
                // (Both return finite values or `None`.)
                let landed = cam
                    .unproject(&p0)
                    .and_then(|z| rows.project_within(cam, &z, guess, NODE_TOLERANCE_PX));
                guess = landed.map(|p| p.y);
                self.nodes
                    .push(landed.map_or([f64::NAN; 2], |p| [p.x - p0.x, p.y - p0.y]));
            }
        }
    }

    /// The landing pixel of the ray whose mid-readout pixel is `p0`,
    /// interpolated; `None` outside the grid or next to a node the lens
    /// cannot see (the caller projects those exactly).
    #[inline]
    pub fn land(&self, p0: &Vector2<f64>) -> Option<Vector2<f64>> {
        if self.nodes.is_empty() {
            return None;
        }
        let fx = (p0.x - self.origin.x) * (1.0 / LANDING_GRID_STEP);
        let fy = (p0.y - self.origin.y) * (1.0 / LANDING_GRID_STEP);
        // Cells with a ring of nodes around them (ordered compares: NaN
        // coordinates fail too).
        if !(fx >= 1.0
            && fy >= 1.0
            && fx < (self.width - 2) as f64
            && fy < (self.height - 2) as f64)
        {
            return None;
        }
        let (ix, iy) = (fx as usize, fy as usize);
        let (wx, wy) = (catmull_rom(fx - ix as f64), catmull_rom(fy - iy as f64));
        // The 4x4 nodes around the cell: along each row, then down.
        let first = (iy - 1) * self.width + ix - 1;
        let block = self.nodes.get(first..first + 3 * self.width + 4)?;
        let (mut dx, mut dy) = (0.0, 0.0);
        for (j, wy) in wy.into_iter().enumerate() {
            let row = &block[j * self.width..][..4];
            let along = |k: usize| {
                wx[0] * row[0][k] + wx[1] * row[1][k] + wx[2] * row[2][k] + wx[3] * row[3][k]
            };
            dx += wy * along(0);
            dy += wy * along(1);
        }
        (dx.is_finite() && dy.is_finite()).then(|| Vector2::new(p0.x + dx, p0.y + dy))
    }
}

/// Catmull-Rom weights of the four nodes around a point `t` (0..1) of the
/// way from the second to the third: a cubic that passes through the nodes,
/// its error falling with the fourth power of the spacing (bilinear's with
/// the second; see `docs/core-history.md#shutter-catmull-rom`).
#[inline]
fn catmull_rom(t: f64) -> [f64; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shutter::IntraFrame;
    use crate::so3::Tangent;

    /// The largest distance (px) between the grid's landing and the exact fixed
    /// point of the same readout table (as the renderer projects), over
    /// mid-readout pixels spread across the frame and its surroundings, and how
    /// many of them the grid answered.
    fn worst_landing(cam: &CameraModel, intra: &IntraFrame) -> (f64, usize) {
        let mut rows = RollingProjector::default();
        rows.set(intra, cam.height);
        let mut grid = LandingGrid::default();
        grid.set(&rows, cam);
        let (mut worst, mut answered) = (0.0f64, 0);
        let (w, h) = (cam.width as f64, cam.height as f64);
        for i in 0..97 {
            for j in 0..61 {
                // Off the node lattice, 10% past each edge.
                let p0 = Vector2::new(
                    -0.1 * w + 1.2 * w * (i as f64 + 0.37) / 97.0,
                    -0.1 * h + 1.2 * h * (j as f64 + 0.61) / 61.0,
                );
                let Some(z) = cam.unproject(&p0) else {
                    continue;
                };
                let exact = rows.project(cam, &z, None);
                match (grid.land(&p0), exact) {
                    (Some(p), Some(q)) => {
                        // Only landings in the frame are ever sampled.
                        if (0.0..=w - 1.0).contains(&q.x) && (0.0..=h - 1.0).contains(&q.y) {
                            worst = worst.max((p - q).norm());
                        }
                        answered += 1;
                    }
                    (Some(p), None) => panic!("{p0} landed at {p} where the lens sees nothing"),
                    (None, _) => {}
                }
            }
        }
        (worst, answered)
    }

    /// A readout turning by `deg` degrees (mostly yaw and pitch, some roll),
    /// its path bent as 12-20 Hz shake bends it.
    fn turn(deg: f64) -> IntraFrame {
        let r = deg.to_radians();
        IntraFrame {
            phi: Tangent::new(0.6 * r, -0.7 * r, 0.35 * r),
            psi: Tangent::new(-0.15 * r, 0.2 * r, 0.05 * r),
            chi: Tangent::new(0.05 * r, -0.03 * r, 0.02 * r),
            xi: Tangent::new(-0.02 * r, 0.01 * r, 0.01 * r),
        }
    }

    /// The interpolated landing stays within 0.005 px of the exact fixed
    /// point (the render grid's own interpolation error) for the readout
    /// turns 100-300 deg/s shake makes through 10-20 ms (1-6 deg), on a
    /// 150 deg fisheye at two sizes, and answers for the frame and its
    /// surroundings (see `docs/core-history.md#shutter-landing-test`).
    #[test]
    fn landing_matches_the_fixed_point() {
        let cams = [
            CameraModel::fisheye_hfov(640, 360, 150.0, [0.05, -0.01, 0.002, -0.0005]).unwrap(),
            CameraModel::fisheye_hfov(320, 180, 150.0, [0.05, -0.01, 0.002, -0.0005]).unwrap(),
        ];
        for cam in &cams {
            for deg in [1.0, 3.0, 6.0] {
                let (worst, answered) = worst_landing(cam, &turn(deg));
                eprintln!(
                    "{}x{} {deg} deg: worst {worst:.2e} px over {answered}",
                    cam.width, cam.height
                );
                assert!(answered >= 97 * 61 * 2 / 3, "{answered}");
                assert!(worst < 5e-3, "{deg} deg: {worst} px");
            }
        }
    }

    /// A global shutter tabulates nothing and answers nothing.
    #[test]
    fn a_global_shutter_has_no_grid() {
        let cam = CameraModel::fisheye_hfov(320, 180, 150.0, [0.0; 4]).unwrap();
        let mut grid = LandingGrid::default();
        grid.set(&RollingProjector::default(), &cam);
        assert!(grid.is_empty());
        assert_eq!(grid.land(&Vector2::new(100.0, 50.0)), None);
    }
}
