//! Each frame's map from output rows to source coordinates: an exact
//! homography for a pinhole source, else a grid of exact nodes.

use super::buffers::RowMap;
use super::{Warper, GRID_STEP, ROLLING_GRID_STEP};
use crate::render::grid;
use crate::shutter::{LandingGrid, RollingProjector};
use nalgebra::Matrix3;

/// The fixed-point tolerance of a grid node's rolling-shutter projection
/// (pixels, see [`RollingProjector::project_within`]): it leaves the node
/// within about a tenth of this (the iteration contracts by under 0.1 per
/// step), far inside the 0.005 px of the grid's interpolation; tighter costs
/// projections for nothing (see `docs/core-history.md#render-node-tolerance-px`).
pub(super) const NODE_TOLERANCE_PX: f64 = 1e-3;

// Both steps fit the grid fill's table of in-cell offsets.
const _: () = assert!(GRID_STEP <= grid::MAX_STEP && ROLLING_GRID_STEP <= grid::MAX_STEP);

impl Warper {
    /// Prepares `map` for rotation `m` (output ray -> source ray) and the
    /// frame's readout rotations `rows`. A distorted source's rolling-shutter
    /// nodes are looked up in the frame's `landing` map when it has one (one
    /// plain projection a node instead of two to three).
    pub(super) fn prepare_map(
        &self,
        map: &mut RowMap,
        m: &Matrix3<f64>,
        rows: &RollingProjector,
        landing: Option<&LandingGrid>,
    ) {
        map.gridded = !self.src.is_pinhole() || !rows.is_global();
        if map.gridded {
            map.grid.clear();
            // Each node starts from the row its two left neighbours' rows
            // extrapolate to (the landing row changes almost linearly along a
            // grid row), or the one left neighbour's, so fewer fixed-point
            // steps are left to take (see `docs/core-history.md#render-node-guess`).
            let (mut prev, mut last) = (None, None);
            for (i, ray) in self.grid_rays.iter().enumerate() {
                if i % self.grid_w == 0 {
                    (prev, last) = (None, None);
                }
                let guess = match (prev, last) {
                    (Some(a), Some(b)) => Some(2.0 * b - a),
                    (_, b) => b,
                };
                let z = m * ray;
                let looked_up =
                    landing.and_then(|grid| self.src.project(&z).and_then(|p0| grid.land(&p0)));
                let p = looked_up
                    .or_else(|| rows.project_within(&self.src, &z, guess, NODE_TOLERANCE_PX));
                (prev, last) = (last, p.map(|p| p.y).filter(|y| y.is_finite()));
                if last.is_none() {
                    prev = None;
                }
                map.grid
                    .push(p.map_or([f32::NAN; 2], |p| [p.x as f32, p.y as f32]));
            }
        } else {
            let k_out_inv = self
                .out
                .k_matrix()
                .try_inverse()
                .unwrap_or_else(Matrix3::identity);
            map.h = (self.src.k_matrix() * m * k_out_inv).map(|v| v as f32);
        }
    }

    /// Maps for `rotations`, in `self.maps` (taken out: give them back after).
    pub(super) fn prepare_maps(&mut self, rotations: &[Matrix3<f64>]) -> Vec<RowMap> {
        let mut maps = std::mem::take(&mut self.maps);
        if !self.rows_changed && self.maps_for == rotations && maps.len() == rotations.len() {
            return maps;
        }
        self.rows_changed = false;
        self.maps_for.clear();
        self.maps_for.extend_from_slice(rotations);
        maps.resize_with(rotations.len(), RowMap::default);
        // A distorted source's frames get their landing maps when they are
        // averaged (a node of the table costs two to three projections, as
        // one of a map, and the table has about as many nodes as a map of
        // the frame at its own size; each of the frame's next maps, one per
        // output it is averaged into, then takes one projection a node).
        // Not for one frame alone, as in saccade mode's slots, where a frame
        // is mapped once per held view and the table would double the work.
        // Whether a map uses the table depends on its render alone, so the
        // bytes of an output never depend on which outputs came before it
        // (the shares of `Stabilizer::set_render_share`). A pinhole's
        // projection is a division: nothing to save.
        let mut landing = std::mem::take(&mut self.landing);
        let tabulate = !self.src.is_pinhole() && rotations.len() > 1;
        if tabulate {
            for (grid, rows) in landing.iter_mut().zip(&self.rows) {
                if grid.is_empty() && !rows.is_global() {
                    grid.set(rows, &self.src);
                }
            }
        }
        let global = RollingProjector::default();
        for (i, (map, m)) in maps.iter_mut().zip(rotations).enumerate() {
            let grid = landing.get(i).filter(|g| tabulate && !g.is_empty());
            self.prepare_map(map, m, self.rows.get(i).unwrap_or(&global), grid);
        }
        self.landing = landing;
        maps
    }

    /// Fills `xs`/`ys` with the source coordinates of output row `v` under `map`.
    pub(super) fn fill_row(&self, map: &RowMap, v: usize, xs: &mut [f32], ys: &mut [f32]) {
        if !map.gridded {
            let h = &map.h;
            let vf = v as f32;
            let (x0, y0, z0) = (
                h[(0, 1)] * vf + h[(0, 2)],
                h[(1, 1)] * vf + h[(1, 2)],
                h[(2, 1)] * vf + h[(2, 2)],
            );
            let (dx, dy, dz) = (h[(0, 0)], h[(1, 0)], h[(2, 0)]);
            // Branch-free so it vectorizes; rays behind the camera become NaN.
            for (u, (xo, yo)) in xs.iter_mut().zip(ys.iter_mut()).enumerate() {
                let uf = u as f32;
                let z = z0 + dz * uf;
                let iz = if z > 1e-6 { 1.0 / z } else { f32::NAN };
                *xo = (x0 + dx * uf) * iz;
                *yo = (y0 + dy * uf) * iz;
            }
        } else {
            grid::interpolate_row(
                &map.grid,
                self.grid_w,
                self.grid_h,
                self.grid_step,
                v,
                xs,
                ys,
            );
        }
    }
}
