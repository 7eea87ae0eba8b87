//! The row engine: a render's frames sampled along each output row by the
//! row kernels, in bands on the rayon pool with the `parallel` feature.

use super::buffers::{RowMap, RowScratch};
use super::{Warper, MAX_FRAMES};
use crate::render::kernels::{
    merge_row_gray_scalar, merge_row_scalar, Geometry, HomographyRow, RowCoords, FRAME_PADDING,
};
use crate::render::robust::Deghost;
use nalgebra::Matrix3;

/// What is fixed for every row of one render: the frames, their maps, the
/// kernel's share of each row.
pub(super) struct Pass<'m, 'd> {
    pub(super) maps: &'m [RowMap],
    pub(super) datas: &'m [&'d [u8]],
    pub(super) geom: Geometry,
    /// Pixels per row the vector kernel handles (a multiple of 8, 0 = none).
    pub(super) n8: usize,
    /// Whether per-frame coordinate tables are needed.
    pub(super) tables: bool,
}

impl Pass<'_, '_> {
    /// Whether any frame is sampled through its grid.
    pub(super) fn any_grid(maps: &[RowMap]) -> bool {
        maps.iter().any(|m| m.gridded)
    }
}

impl Warper {
    /// The start of a render of the frames of `rotations` on the render grid:
    /// `coverage` zeroed at its size, the frames' maps (to hand back to
    /// `self.maps` after), and how many frames are rendered (at most
    /// [`MAX_FRAMES`]).
    pub(super) fn begin_render(
        &mut self,
        rotations: &[Matrix3<f64>],
        coverage: &mut Vec<u8>,
    ) -> (Vec<RowMap>, usize) {
        let (ow, oh) = (self.out.width, self.out.height);
        coverage.clear();
        coverage.resize(ow * oh, 0);
        let maps = self.prepare_maps(rotations);
        (maps, rotations.len().min(MAX_FRAMES))
    }

    /// The pass over `datas` (frames or planes with geometry `geom`, sampled
    /// with this warper's interpolation): the first
    /// `n8` pixels of a row (a multiple of 8) go to the vector kernel when it is
    /// available and every buffer carries the gathers' padding; the rest are
    /// scalar. The kernel evaluates pinhole homographies itself, so coordinate
    /// tables are needed only for distorted sources and for scalar pixels.
    pub(super) fn pass<'m, 'd>(
        &self,
        maps: &'m [RowMap],
        datas: &'m [&'d [u8]],
        geom: Geometry,
        rows: usize,
    ) -> Pass<'m, 'd> {
        let ow = self.out.width;
        let padded = datas
            .iter()
            .all(|d| d.len() >= geom.stride * rows + FRAME_PADDING);
        let n8 = if self.kernel.is_vectorized() && padded {
            ow / 8 * 8
        } else {
            0
        };
        Pass {
            maps,
            datas,
            geom: geom.with_cubic(self.cubic()),
            n8,
            tables: Pass::any_grid(maps) || n8 < ow,
        }
    }

    /// Runs the vector kernel over the first `n8` pixels of row `v` of every
    /// frame of `pass`, into `scratch.sums` (three channels, or one when
    /// `gray`) and `scratch.count`, after filling the coordinate tables. With
    /// `pair` (a second plane of the same geometry and maps, gray), its sums
    /// go to `scratch.sums[1]`.
    pub(super) fn accumulate_row(
        &self,
        pass: &Pass<'_, '_>,
        pair: Option<&Pass<'_, '_>>,
        v: usize,
        scratch: &mut RowScratch,
        gray: bool,
    ) {
        if pass.tables {
            for (f, map) in pass.maps.iter().enumerate() {
                self.fill_row(map, v, &mut scratch.xs[f], &mut scratch.ys[f]);
            }
        }
        if pass.n8 == 0 {
            return;
        }
        let coords = Self::row_coords(pass, v, &scratch.xs, &scratch.ys);
        let n = pass.maps.len().min(pass.datas.len()).min(MAX_FRAMES);
        let [r, g, b] = &mut scratch.sums;
        // SAFETY: `self.kernel` comes from `Kernel::detect` (vectorized only when
        // `n8 > 0`, a multiple of 8); `pass` checked every buffer's padding (the
        // whole frame or plane plus `FRAME_PADDING` bytes), and so did `pair`
        // (the same `n8`); all row buffers hold `ow >= n8` values.
        unsafe {
            if let Some(pair) = pair {
                debug_assert!(gray && pair.n8 == pass.n8 && pair.datas.len() >= n);
                self.kernel.accumulate_row_gray_pair(
                    &pass.datas[..n],
                    &pair.datas[..n],
                    &pass.geom,
                    &coords[..n],
                    pass.n8,
                    r,
                    g,
                    &mut scratch.count,
                );
            } else if gray {
                self.kernel.accumulate_row_gray(
                    &pass.datas[..n],
                    &pass.geom,
                    &coords[..n],
                    pass.n8,
                    r,
                    &mut scratch.count,
                );
            } else {
                self.kernel.accumulate_row(
                    &pass.datas[..n],
                    &pass.geom,
                    &coords[..n],
                    pass.n8,
                    r,
                    g,
                    b,
                    &mut scratch.count,
                );
            }
        }
    }

    /// Each frame's source coordinates along row `v` for the kernels: its
    /// homography row (pinhole maps) or its table in `xs`/`ys` (grids).
    pub(super) fn row_coords<'s>(
        pass: &Pass<'_, '_>,
        v: usize,
        xs: &'s [Vec<f32>],
        ys: &'s [Vec<f32>],
    ) -> [RowCoords<'s>; MAX_FRAMES] {
        let mut coords = [RowCoords::Table(&[], &[]); MAX_FRAMES];
        let vf = v as f32;
        for (f, map) in pass.maps.iter().enumerate().take(MAX_FRAMES) {
            coords[f] = if !map.gridded {
                let h = &map.h;
                RowCoords::Homography(HomographyRow {
                    x0: h[(0, 1)] * vf + h[(0, 2)],
                    y0: h[(1, 1)] * vf + h[(1, 2)],
                    z0: h[(2, 1)] * vf + h[(2, 2)],
                    dx: h[(0, 0)],
                    dy: h[(1, 0)],
                    dz: h[(2, 0)],
                })
            } else {
                RowCoords::Table(&xs[f], &ys[f])
            };
        }
        coords
    }

    /// The ghost-free row (see [`crate::render::robust`]): every frame of `pass` sampled
    /// along row `v` and weighted by its agreement with the last (newest)
    /// frame, by the vector kernel for the first `n8` pixels and the scalar
    /// reference for the rest: weighted sums in `scratch.sums` (three channels,
    /// or one when `gray`), the weights' sum in `scratch.weight` and the
    /// covering frames in `scratch.count`, for every pixel. With `pair` (a second
    /// plane of the same geometry, `gray` only) its sums go to `scratch.sums[1]`
    /// and its weights to `scratch.weight_b`, its taps found with the first's.
    pub(super) fn merge_row(
        &self,
        pass: &Pass<'_, '_>,
        pair: Option<&Pass<'_, '_>>,
        v: usize,
        scratch: &mut RowScratch,
        gray: bool,
        deghost: Deghost,
    ) {
        let ow = self.out.width;
        if pass.tables {
            for (f, map) in pass.maps.iter().enumerate() {
                self.fill_row(map, v, &mut scratch.xs[f], &mut scratch.ys[f]);
            }
        }
        let n = pass.maps.len().min(pass.datas.len()).min(MAX_FRAMES);
        let coords = Self::row_coords(pass, v, &scratch.xs, &scratch.ys);
        let (datas, coords, geom) = (&pass.datas[..n], &coords[..n], &pass.geom);
        let [r, g, b] = &mut scratch.sums;
        let (weight, weight_b, count) = (
            &mut scratch.weight,
            &mut scratch.weight_b,
            &mut scratch.count,
        );
        // SAFETY: as in `accumulate_row`: the kernel comes from `Kernel::detect`
        // (vectorized only when `n8 > 0`, a multiple of 8), `pass` checked the
        // padding (and `pair`, of the same `n8`), every row buffer holds
        // `ow >= n8` values, and `n >= 2`.
        unsafe {
            if let Some(pair) = pair.filter(|_| pass.n8 > 0) {
                debug_assert!(gray && pair.n8 == pass.n8 && pair.datas.len() >= n);
                self.kernel.merge_row_gray_pair(
                    (datas, &pair.datas[..n]),
                    geom,
                    coords,
                    deghost,
                    pass.n8,
                    (&mut *r, &mut *g),
                    (&mut *weight, &mut *weight_b),
                    count,
                );
            } else if gray {
                if pass.n8 > 0 {
                    self.kernel
                        .merge_row_gray(datas, geom, coords, deghost, pass.n8, r, weight, count);
                }
            } else if pass.n8 > 0 {
                self.kernel.merge_row(
                    datas,
                    geom,
                    coords,
                    deghost,
                    pass.n8,
                    [&mut *r, &mut *g, &mut *b],
                    weight,
                    count,
                );
            }
        }
        // The rest of the row through the tables (`pass.tables` whenever `n8 < ow`).
        if pass.n8 < ow {
            let mut table = [RowCoords::Table(&[], &[]); MAX_FRAMES];
            for (t, (xs, ys)) in table.iter_mut().zip(scratch.xs.iter().zip(&scratch.ys)) {
                *t = RowCoords::Table(xs, ys);
            }
            let span = (pass.n8, ow);
            if let Some(pair) = pair {
                let (table, pair_datas) = (&table[..n], &pair.datas[..n]);
                merge_row_gray_scalar(datas, geom, table, deghost, span, r, weight, count);
                merge_row_gray_scalar(pair_datas, geom, table, deghost, span, g, weight_b, count);
            } else if gray {
                merge_row_gray_scalar(datas, geom, &table[..n], deghost, span, r, weight, count);
            } else {
                merge_row_scalar(
                    datas,
                    geom,
                    &table[..n],
                    deghost,
                    span,
                    [r, g, b],
                    weight,
                    count,
                );
            }
        }
    }

    /// Calls `row(scratch, v, out_row, coverage_row)` for every output row and
    /// sums what it returns: in bands on the rayon pool with the `parallel`
    /// feature and more than one thread, else in order with the warper's buffers.
    pub(super) fn for_each_row<F>(
        &mut self,
        out: &mut [u8],
        row_bytes: usize,
        coverage: &mut [u8],
        row: F,
    ) -> usize
    where
        F: Fn(&Self, &mut RowScratch, usize, &mut [u8], &mut [u8]) -> usize + Sync,
    {
        let (ow, oh) = (self.out.width, self.out.height);
        let out = &mut out[..row_bytes * oh];
        let coverage = &mut coverage[..ow * oh];
        #[cfg(feature = "parallel")]
        {
            use rayon::prelude::*;
            let threads = rayon::current_num_threads();
            if threads > 1 && oh >= 2 * threads {
                // Twelve bands per thread, so a band that samples slowly (strong
                // rotation, cache misses) or a thread that joins late (from the
                // next frame's tracking) leaves the others little to wait for.
                let band = oh.div_ceil(12 * threads);
                let mut scratches = std::mem::take(&mut self.band_scratch);
                scratches.resize_with(oh.div_ceil(band), RowScratch::default);
                let this = &*self;
                let complete = out
                    .par_chunks_mut(band * row_bytes)
                    .zip(coverage.par_chunks_mut(band * ow))
                    .zip(scratches.par_iter_mut())
                    .enumerate()
                    .map(|(b, ((o, c), scratch))| {
                        o.chunks_mut(row_bytes)
                            .zip(c.chunks_mut(ow))
                            .enumerate()
                            .map(|(i, (orow, crow))| row(this, scratch, b * band + i, orow, crow))
                            .sum::<usize>()
                    })
                    .sum();
                self.band_scratch = scratches;
                return complete;
            }
        }
        let mut scratch = std::mem::take(&mut self.scratch);
        let complete = out
            .chunks_mut(row_bytes)
            .zip(coverage.chunks_mut(ow))
            .enumerate()
            .map(|(v, (orow, crow))| row(self, &mut scratch, v, orow, crow))
            .sum();
        self.scratch = scratch;
        complete
    }
}
