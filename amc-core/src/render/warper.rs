//! The warper: maps output rows to source coordinates (an exact homography for
//! pinhole sources, an interpolated grid of the exact lens map otherwise) and
//! samples every frame there, through the row kernels.
//!
//! Interleaved frames (RGB, RGBA) are sampled three channels at a time; planar
//! frames one plane at a time, each plane by a warper whose cameras are that
//! plane's (the chroma planes of 4:2:0 frames by one built for the half-size
//! cameras, [`chroma_camera`]): one geometry, three planes.
//!
//! Supersampling (anti-aliasing of minified outputs, [`super::Antialias`]):
//! a warper built with `S > 1` ([`Warper::supersampled`]) renders every output
//! through the same kernels into a grid `S` times finer per axis, the output
//! camera rescaled pixel-centre correct (`f' = S f`, `c' = S c + (S - 1) / 2`:
//! fine pixel `S i + k` looks along the ray of output position
//! `i + (k - (S - 1) / 2) / S`, so the `S x S` samples of a pixel are spread
//! evenly over it around its centre), then averages each `S x S` block in
//! integers ([`box_down`], [`box_down_slot`]): the same bytes whatever the
//! kernel. With `S = 1` nothing of this runs and the output is the plain one.
//!
//! Output rows are independent. With the `parallel` feature, a frame's rows
//! are rendered in bands on the current rayon pool (each band with row buffers
//! of its own); the bytes are the same whatever the number of threads.

use super::accumulator::WarpedFrame;
use super::grid;
use super::kernels::{
    average, merge_row_gray_scalar, merge_row_scalar, Geometry, Kernel, RowCoords, FRAME_PADDING,
};
use super::params::{Interpolation, MAX_SUPERSAMPLE};
use super::robust::{weighted_average, Deghost};
use crate::camera::CameraModel;
use crate::image::FrameRef;
use crate::shutter::{LandingGrid, RollingProjector};
use nalgebra::{Matrix3, Vector2, Vector3};

/// Grid spacing (output pixels) of the exact lens map for distorted sources.
pub const GRID_STEP: usize = 8;
/// Grid spacing (output pixels) of a pinhole source's map through a rolling
/// shutter: the map is a homography bent smoothly by the readout motion, and
/// bilinear interpolation over 16 px cells stays within 0.005 px of it (a
/// 90 deg lens turned by 5 deg); a quarter of the nodes of [`GRID_STEP`].
pub const ROLLING_GRID_STEP: usize = 16;
/// The fixed-point tolerance of a grid node's rolling-shutter projection
/// (pixels, see [`RollingProjector::project_within`]): it leaves the node
/// within about a tenth of this (the iteration contracts by under 0.1 per
/// step), far inside the 0.005 px of the grid's interpolation; at a tenth of
/// it, a 320x180 run's nodes took 3.3 projections each instead of 3.1.
const NODE_TOLERANCE_PX: f64 = 1e-3;
// Both steps fit the grid fill's table of in-cell offsets.
const _: () = assert!(GRID_STEP <= grid::MAX_STEP && ROLLING_GRID_STEP <= grid::MAX_STEP);

/// The camera of a 4:2:0 chroma plane of frames seen through `cam`: half the
/// focal length, and chroma sample `u` at luma position `2 u + 0.5` (centred
/// siting), so `c' = (c - 0.5) / 2`; the size is the chroma plane's
/// (`ceil` of halves). Lens distortion acts on normalized coordinates and is kept.
pub fn chroma_camera(cam: &CameraModel) -> CameraModel {
    let (w, h) = crate::image::chroma_size(cam.width, cam.height);
    CameraModel {
        width: w,
        height: h,
        fx: cam.fx / 2.0,
        fy: cam.fy / 2.0,
        cx: (cam.cx - 0.5) / 2.0,
        cy: (cam.cy - 0.5) / 2.0,
        skew: cam.skew / 2.0,
        distortion: cam.distortion.clone(),
    }
}

/// How one frame's source coordinates are produced along output rows.
#[derive(Clone, Debug, Default)]
struct RowMap {
    /// Homography `K_src M K_out^-1` (pinhole sources, global shutter).
    h: Matrix3<f32>,
    /// Exact source coordinates at the grid nodes (distorted sources, and any
    /// source through a rolling shutter).
    grid: Vec<[f32; 2]>,
    /// Whether this map is the grid (else the homography).
    gridded: bool,
}

/// Per-row working buffers: one set per band of rows being rendered.
#[derive(Clone, Debug, Default)]
struct RowScratch {
    /// Source coordinates `(xs[f][u], ys[f][u])` of the current row per frame (NaN: none).
    xs: Vec<Vec<f32>>,
    ys: Vec<Vec<f32>>,
    /// Per-channel sums of the vectorized path (1 or 3 used).
    sums: [Vec<u32>; 3],
    /// Frames covering each pixel of the row.
    count: Vec<u32>,
    /// Ghost-free averaging: the weights' sum per pixel (`sums` then holds
    /// the weighted sums).
    weight: Vec<u32>,
}

impl RowScratch {
    /// Sizes the buffers for `frames` frames of rows `width` wide (with the
    /// weights when `merged`).
    fn fit(&mut self, frames: usize, width: usize, tables: bool, merged: bool) {
        if tables {
            self.xs.resize_with(frames, Vec::new);
            self.ys.resize_with(frames, Vec::new);
            for t in self.xs.iter_mut().chain(self.ys.iter_mut()) {
                t.resize(width, 0.0);
            }
        }
        for buf in self.sums.iter_mut().chain(std::iter::once(&mut self.count)) {
            buf.resize(width, 0);
        }
        if merged {
            self.weight.resize(width, 0);
        }
    }
}

/// The supersampled renders of a warper with `S > 1`, before their `S x S`
/// blocks are averaged into the caller's buffers (kept: a warmed-up render
/// allocates nothing).
#[derive(Clone, Debug, Default)]
struct Fine {
    /// Image (interleaved or one plane) and its second plane (U and V pairs).
    image: Vec<u8>,
    image_b: Vec<u8>,
    /// Covering frames per fine pixel.
    coverage: Vec<u8>,
    /// A saccade slot's samples and coverage (interleaved or one plane).
    slot: WarpedFrame,
}

/// Samples source frames along rotated output rays.
#[derive(Clone, Debug)]
pub struct Warper {
    src: CameraModel,
    /// The camera rendered through: the output's, or its `S`-times finer grid
    /// when supersampling (every row method below works on this grid).
    out: CameraModel,
    /// The caller's output size (`out`'s divided by `supersample`).
    view_w: usize,
    view_h: usize,
    /// Samples per axis of each output pixel, `S` (1: none).
    supersample: usize,
    /// The fine renders of `S > 1`.
    fine: Fine,
    /// Output rays at the grid nodes.
    grid_rays: Vec<Vector3<f64>>,
    grid_w: usize,
    grid_h: usize,
    /// Spacing of the grid nodes, output pixels.
    grid_step: usize,
    maps: Vec<RowMap>,
    /// The row kernel: a vectorized one (AVX-512 or AVX2 on this CPU, or wasm `simd128`)
    /// or the scalar reference, which leaves every pixel to the per-pixel path.
    kernel: Kernel,
    /// Readout rotations of the frames of the next render, in the order of
    /// its rotations ([`Warper::set_readout_rows`]); empty for a global shutter.
    rows: Vec<RollingProjector>,
    /// Each of those frames' tabulated landing map, for distorted sources
    /// (see [`Warper::set_readout_rows`]; empty until its first map).
    landing: Vec<LandingGrid>,
    /// Frames of earlier calls and their landing maps, kept for their
    /// memory (and in case they come back).
    spare_rows: Vec<RollingProjector>,
    spare_landing: Vec<LandingGrid>,
    /// The rotations `maps` were last prepared for, and whether the readout
    /// rows changed since: the U and V planes of a frame share one geometry,
    /// so the second plane reuses the first one's maps.
    maps_for: Vec<Matrix3<f64>>,
    rows_changed: bool,
    /// Ghost-free averaging ([`Warper::set_deghost`]); `None`: the plain average.
    deghost: Option<Deghost>,
    /// How frames are sampled between pixels ([`Warper::set_interpolation`]).
    interpolation: Interpolation,
    /// Row buffers of the sequential path.
    scratch: RowScratch,
    /// Row buffers of the bands of the parallel path (one per band, kept so
    /// that a warmed-up render allocates nothing).
    #[cfg_attr(not(feature = "parallel"), allow(dead_code))]
    band_scratch: Vec<RowScratch>,
    /// [`Warper::average_plane_pair_into`]'s rows of both planes (reused).
    pair_rows: Vec<u8>,
}

/// Most frames one output may average (the range of `n_avg`).
const MAX_FRAMES: usize = 64;

/// What is fixed for every row of one render: the frames, their maps, the
/// kernel's share of each row.
struct Pass<'m, 'd> {
    maps: &'m [RowMap],
    datas: &'m [&'d [u8]],
    geom: Geometry,
    /// Pixels per row the vector kernel handles (a multiple of 8, 0 = none).
    n8: usize,
    /// Whether per-frame coordinate tables are needed.
    tables: bool,
}

impl Pass<'_, '_> {
    /// Whether any frame is sampled through its grid.
    fn any_grid(maps: &[RowMap]) -> bool {
        maps.iter().any(|m| m.gridded)
    }
}

impl Warper {
    /// A warper from frames of `src` into `out` (a pinhole), one sample per
    /// output pixel.
    pub fn new(src: &CameraModel, out: &CameraModel) -> Self {
        Self::supersampled(src, out, 1)
    }

    /// A warper from frames of `src` into `out` (a pinhole) that averages
    /// `supersample x supersample` samples per output pixel (clamped to
    /// `1..=MAX_SUPERSAMPLE`; see the module's docs and
    /// [`super::RenderParams::supersample`]). `S^2` times the sampling work.
    pub fn supersampled(src: &CameraModel, view: &CameraModel, supersample: usize) -> Self {
        let s = supersample.clamp(1, MAX_SUPERSAMPLE);
        // `S = 1` keeps the camera as it is (rescaling by 1 could round).
        let out = if s == 1 {
            view.clone()
        } else {
            view.rescaled(s * view.width, s * view.height)
        };
        // Grid nodes for distorted sources and rolling shutters (a pinhole
        // source needs them only once a frame has a readout motion).
        let grid_step = if src.is_pinhole() {
            ROLLING_GRID_STEP
        } else {
            GRID_STEP
        };
        let grid_w = out.width.div_ceil(grid_step) + 1;
        let grid_h = out.height.div_ceil(grid_step) + 1;
        let mut grid_rays = Vec::with_capacity(grid_w * grid_h);
        for gy in 0..grid_h {
            for gx in 0..grid_w {
                let p = Vector2::new((gx * grid_step) as f64, (gy * grid_step) as f64);
                grid_rays.push(out.unproject(&p).unwrap_or_else(Vector3::z));
            }
        }
        Self {
            src: src.clone(),
            out,
            view_w: view.width,
            view_h: view.height,
            supersample: s,
            fine: Fine::default(),
            grid_rays,
            grid_w,
            grid_h,
            grid_step,
            maps: Vec::new(),
            kernel: Kernel::detect(),
            rows: Vec::new(),
            landing: Vec::new(),
            spare_rows: Vec::new(),
            spare_landing: Vec::new(),
            maps_for: Vec::new(),
            rows_changed: false,
            deghost: None,
            interpolation: Interpolation::Bilinear,
            scratch: RowScratch::default(),
            band_scratch: Vec::new(),
            pair_rows: Vec::new(),
        }
    }

    /// Runs `kernel` instead of the detected one, for benches and tests that
    /// compare kernels; returns `false` and keeps the current kernel when this
    /// build or CPU cannot run it (see [`Kernel::available`]).
    pub fn set_kernel(&mut self, kernel: Kernel) -> bool {
        let runnable = Kernel::available().contains(&kernel);
        if runnable {
            self.kernel = kernel;
        }
        runnable
    }

    /// Disables the vectorized path (for testing the scalar one against it).
    pub fn set_vectorized(&mut self, on: bool) {
        self.kernel = if on { Kernel::detect() } else { Kernel::Scalar };
    }

    /// Averages of several frames ([`Warper::average_into`],
    /// [`Warper::average_plane_into`]) weight each frame's pixel by its
    /// agreement with the last frame's (see [`super::robust`]); `None` (the
    /// default) averages plainly.
    pub fn set_deghost(&mut self, deghost: Option<Deghost>) {
        self.deghost = deghost;
    }

    /// The ghost-free averaging set by [`Warper::set_deghost`]; `None`: the plain average.
    pub fn deghost(&self) -> Option<Deghost> {
        self.deghost
    }

    /// Samples frames between their pixels bilinearly (the default) or
    /// bicubically (see [`Interpolation`]); every render and warp after it.
    pub fn set_interpolation(&mut self, interpolation: Interpolation) {
        self.interpolation = interpolation;
    }

    /// The interpolation set by [`Warper::set_interpolation`].
    pub fn interpolation(&self) -> Interpolation {
        self.interpolation
    }

    /// Whether frames are sampled bicubically.
    fn cubic(&self) -> bool {
        self.interpolation == Interpolation::Bicubic
    }

    /// Output size.
    pub fn output_size(&self) -> (usize, usize) {
        (self.view_w, self.view_h)
    }

    /// Samples per axis of each output pixel (1: no supersampling).
    pub fn supersample(&self) -> usize {
        self.supersample
    }

    /// Size of the grid sampled: the output's times [`Warper::supersample`]
    /// (what [`Warper::warp`] indexes).
    pub fn render_size(&self) -> (usize, usize) {
        (self.out.width, self.out.height)
    }

    /// Sets the readout rotations of the frames of the next renders (a
    /// rolling shutter: [`RollingProjector`] tables of the sensor's rows), one
    /// per rotation they are given, in the same order: every
    /// source row is then sampled at its own orientation (see
    /// [`crate::shutter::project_rolling`]; exact at the grid nodes, bilinear
    /// between them). Empty (the default) for a global shutter. Frames beyond
    /// the list, or with empty tables, are sampled as with a global shutter.
    ///
    /// A distorted source's frames each get a [`LandingGrid`] when they are
    /// rendered averaged with others: their nodes then take one projection
    /// through the lens and a lookup instead of two to three projections,
    /// within 0.005 px of the fixed point. A frame passed again in a later
    /// call (the averaging window moving on) keeps its grid; the frames not
    /// passed again are forgotten.
    pub fn set_readout_rows<'r>(&mut self, rows: impl IntoIterator<Item = &'r RollingProjector>) {
        // The frames of the last call are set aside: one passed again (the
        // averaging window moving on) is found there with its landing map,
        // and a new one takes the memory of one that left (a frame passed
        // again after that is then mapped afresh).
        self.spare_rows.append(&mut self.rows);
        self.spare_landing.append(&mut self.landing);
        for src in rows {
            let (rows, landing) = match self.spare_rows.iter().position(|r| r == src) {
                Some(k) => (
                    self.spare_rows.swap_remove(k),
                    self.spare_landing.swap_remove(k),
                ),
                None => {
                    let mut rows = self.spare_rows.pop().unwrap_or_default();
                    let mut landing = self.spare_landing.pop().unwrap_or_default();
                    rows.clone_from(src);
                    landing.clear();
                    (rows, landing)
                }
            };
            self.rows.push(rows);
            self.landing.push(landing);
        }
        self.rows_changed = true;
    }

    /// The readout rotations set by [`Warper::set_readout_rows`].
    pub fn readout_rows(&self) -> &[RollingProjector] {
        &self.rows
    }

    /// Prepares `map` for rotation `m` (output ray -> source ray) and the
    /// frame's readout rotations `rows`. A distorted source's rolling-shutter
    /// nodes are looked up in the frame's `landing` map when it has one (one
    /// plain projection a node instead of two to three).
    fn prepare_map(
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
            // steps are left to take (the nodes' projections went from 11.6%
            // to 10.7% of a 320x180 run with a 15 ms readout).
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
    fn prepare_maps(&mut self, rotations: &[Matrix3<f64>]) -> Vec<RowMap> {
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

    /// The pass over `datas` (frames or planes with geometry `geom`, sampled
    /// with this warper's interpolation): the first
    /// `n8` pixels of a row (a multiple of 8) go to the vector kernel when it is
    /// available and every buffer carries the gathers' padding; the rest are
    /// scalar. The kernel evaluates pinhole homographies itself, so coordinate
    /// tables are needed only for distorted sources and for scalar pixels.
    fn pass<'m, 'd>(
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

    /// Fills `xs`/`ys` with the source coordinates of output row `v` under `map`.
    fn fill_row(&self, map: &RowMap, v: usize, xs: &mut [f32], ys: &mut [f32]) {
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

    /// Runs the vector kernel over the first `n8` pixels of row `v` of every
    /// frame of `pass`, into `scratch.sums` (three channels, or one when
    /// `gray`) and `scratch.count`, after filling the coordinate tables. With
    /// `pair` (a second plane of the same geometry and maps, gray), its sums
    /// go to `scratch.sums[1]`.
    fn accumulate_row(
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
    fn row_coords<'s>(
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
                RowCoords::Homography {
                    x0: h[(0, 1)] * vf + h[(0, 2)],
                    y0: h[(1, 1)] * vf + h[(1, 2)],
                    z0: h[(2, 1)] * vf + h[(2, 2)],
                    dx: h[(0, 0)],
                    dy: h[(1, 0)],
                    dz: h[(2, 0)],
                }
            } else {
                RowCoords::Table(&xs[f], &ys[f])
            };
        }
        coords
    }

    /// The ghost-free row (see [`super::robust`]): every frame of `pass` sampled
    /// along row `v` and weighted by its agreement with the last (newest)
    /// frame, by the vector kernel for the first `n8` pixels and the scalar
    /// reference for the rest: weighted sums in `scratch.sums` (three channels,
    /// or one when `gray`), the weights' sum in `scratch.weight` and the
    /// covering frames in `scratch.count`, for every pixel.
    fn merge_row(
        &self,
        pass: &Pass<'_, '_>,
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
        let (weight, count) = (&mut scratch.weight, &mut scratch.count);
        // SAFETY: as in `accumulate_row`: the kernel comes from `Kernel::detect`
        // (vectorized only when `n8 > 0`, a multiple of 8), `pass` checked the
        // padding, every row buffer holds `ow >= n8` values, and `n >= 2`.
        unsafe {
            if gray {
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
            if gray {
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
    fn for_each_row<F>(
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
                // A few bands per thread, so a band that samples slowly (strong
                // rotation, cache misses) does not leave the others idle.
                let band = oh.div_ceil(4 * threads);
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

    /// Renders the average of frames `frame_at(0..n)` (with `rotations[i]`, the
    /// output->source rotation of frame `i`) into `out` (interleaved, `channels`
    /// 3 or 4) in one pass: per output row the source coordinates of every
    /// frame are computed into small row buffers, then each pixel samples all
    /// frames and is written once. `coverage` receives the per-pixel count of
    /// covering frames. Returns the share of pixels covered by every frame.
    /// Supersampled: each pixel is its block's [`box_down`], its coverage the
    /// block's least.
    pub fn average_into<'a, F: Fn(usize) -> FrameRef<'a>>(
        &mut self,
        frame_at: F,
        rotations: &[Matrix3<f64>],
        out: &mut [u8],
        channels: usize,
        coverage: &mut Vec<u8>,
    ) -> f64 {
        if self.supersample == 1 {
            return self.render_average_into(frame_at, rotations, out, channels, coverage);
        }
        let (ow, oh) = (self.view_w, self.view_h);
        let mut fine = std::mem::take(&mut self.fine);
        fine.image
            .resize(self.out.width * self.out.height * channels, 0);
        self.render_average_into(
            frame_at,
            rotations,
            &mut fine.image,
            channels,
            &mut fine.coverage,
        );
        let full = rotations.len() as u8;
        let complete = self.finish_fine(&fine.image, &fine.coverage, channels, full, out, coverage);
        self.fine = fine;
        complete as f64 / (ow * oh).max(1) as f64
    }

    /// [`Warper::average_into`] on the render grid.
    fn render_average_into<'a, F: Fn(usize) -> FrameRef<'a>>(
        &mut self,
        frame_at: F,
        rotations: &[Matrix3<f64>],
        out: &mut [u8],
        channels: usize,
        coverage: &mut Vec<u8>,
    ) -> f64 {
        let (ow, oh) = (self.out.width, self.out.height);
        coverage.clear();
        coverage.resize(ow * oh, 0);
        let maps = self.prepare_maps(rotations);
        let full = rotations.len() as u8;
        let n_frames = rotations.len().min(MAX_FRAMES);
        // Hoist each frame's pixels out of the per-pixel loop.
        let mut datas: [&[u8]; MAX_FRAMES] = [&[]; MAX_FRAMES];
        let first = frame_at(0);
        for (f, d) in datas.iter_mut().enumerate().take(n_frames) {
            let fr = frame_at(f);
            if fr.width == first.width && fr.height == first.height && fr.format == first.format {
                *d = fr.data;
            }
        }
        let pass = self.pass(
            &maps[..n_frames],
            &datas[..n_frames],
            Geometry::of(&first),
            first.height,
        );
        let merged = self.deghost.filter(|_| n_frames > 1);
        let complete = self.for_each_row(
            out,
            ow * channels,
            coverage,
            |w, scratch, v, out_row, cov_row| {
                scratch.fit(n_frames, ow, pass.tables, merged.is_some());
                if let Some(deghost) = merged {
                    w.merge_row(&pass, v, scratch, false, deghost);
                    finish_merged_rgb_row(w.kernel, scratch, out_row, cov_row, channels, full)
                } else {
                    w.accumulate_row(&pass, None, v, scratch, false);
                    finish_rgb_row(w.kernel, &pass, scratch, out_row, cov_row, channels, full)
                }
            },
        );
        self.maps = maps;
        complete as f64 / (ow * oh).max(1) as f64
    }

    /// Renders the average of one plane of several planar frames: `plane_at(i)`
    /// is frame `i`'s plane (`width x height` bytes, rows packed, followed by at
    /// least [`FRAME_PADDING`] readable bytes for the vector kernel, else it
    /// runs scalar), sampled with this warper's cameras (the plane's) through
    /// `rotations[i]`. Writes the rounded average into `out` (this warper's
    /// output size) and the covering frames per pixel into `coverage` (resized);
    /// pixels no frame covers get `fill`. Returns how many pixels every frame covers.
    /// Supersampled: as [`Warper::average_into`].
    #[allow(clippy::too_many_arguments)]
    pub fn average_plane_into<'a, F: Fn(usize) -> &'a [u8]>(
        &mut self,
        plane_at: F,
        width: usize,
        height: usize,
        rotations: &[Matrix3<f64>],
        out: &mut [u8],
        coverage: &mut Vec<u8>,
        fill: u8,
    ) -> usize {
        if self.supersample == 1 {
            return self.render_plane_into(plane_at, width, height, rotations, out, coverage, fill);
        }
        let mut fine = std::mem::take(&mut self.fine);
        fine.image.resize(self.out.width * self.out.height, 0);
        self.render_plane_into(
            plane_at,
            width,
            height,
            rotations,
            &mut fine.image,
            &mut fine.coverage,
            fill,
        );
        let full = rotations.len() as u8;
        let complete = self.finish_fine(&fine.image, &fine.coverage, 1, full, out, coverage);
        self.fine = fine;
        complete
    }

    /// [`Warper::average_plane_into`] on the render grid.
    #[allow(clippy::too_many_arguments)]
    fn render_plane_into<'a, F: Fn(usize) -> &'a [u8]>(
        &mut self,
        plane_at: F,
        width: usize,
        height: usize,
        rotations: &[Matrix3<f64>],
        out: &mut [u8],
        coverage: &mut Vec<u8>,
        fill: u8,
    ) -> usize {
        let (ow, oh) = (self.out.width, self.out.height);
        coverage.clear();
        coverage.resize(ow * oh, 0);
        let maps = self.prepare_maps(rotations);
        let full = rotations.len() as u8;
        let n_frames = rotations.len().min(MAX_FRAMES);
        let mut datas: [&[u8]; MAX_FRAMES] = [&[]; MAX_FRAMES];
        for (f, d) in datas.iter_mut().enumerate().take(n_frames) {
            let p = plane_at(f);
            if p.len() >= width * height {
                *d = p;
            }
        }
        let pass = self.pass(
            &maps[..n_frames],
            &datas[..n_frames],
            Geometry::plane(width, height, 1),
            height,
        );
        let merged = self.deghost.filter(|_| n_frames > 1);
        let complete = self.for_each_row(out, ow, coverage, |w, scratch, v, out_row, cov_row| {
            scratch.fit(n_frames, ow, pass.tables, merged.is_some());
            if let Some(deghost) = merged {
                w.merge_row(&pass, v, scratch, true, deghost);
                finish_merged_gray_row(scratch, out_row, cov_row, full, fill)
            } else {
                w.accumulate_row(&pass, None, v, scratch, true);
                finish_gray_row(w.kernel, &pass, scratch, 0, out_row, cov_row, full, fill)
            }
        });
        self.maps = maps;
        complete
    }

    /// [`Warper::average_plane_into`] of two planes of one size through the
    /// same rotations (the U and V planes of 4:2:0 frames): `planes_at(i)` is
    /// frame `i`'s pair, the averages go to `out_a` and `out_b`, the covering
    /// frames (the same for both) to `coverage`. The vector kernels sample both
    /// planes along a row at once, finding each pixel's taps once (see
    /// [`Kernel::accumulate_row_gray_pair`]); ghost-free averaging and
    /// unpadded planes take the planes one after the other. Returns how many
    /// pixels every frame covers. Supersampled: as [`Warper::average_into`].
    #[allow(clippy::too_many_arguments)]
    pub fn average_plane_pair_into<'a, F: Fn(usize) -> (&'a [u8], &'a [u8])>(
        &mut self,
        planes_at: F,
        width: usize,
        height: usize,
        rotations: &[Matrix3<f64>],
        out_a: &mut [u8],
        out_b: &mut [u8],
        coverage: &mut Vec<u8>,
        fill: u8,
    ) -> usize {
        if self.supersample == 1 {
            return self.render_plane_pair_into(
                planes_at, width, height, rotations, out_a, out_b, coverage, fill,
            );
        }
        let mut fine = std::mem::take(&mut self.fine);
        let n = self.out.width * self.out.height;
        fine.image.resize(n, 0);
        fine.image_b.resize(n, 0);
        self.render_plane_pair_into(
            planes_at,
            width,
            height,
            rotations,
            &mut fine.image,
            &mut fine.image_b,
            &mut fine.coverage,
            fill,
        );
        let full = rotations.len() as u8;
        let complete = self.finish_fine(&fine.image, &fine.coverage, 1, full, out_a, coverage);
        self.finish_fine(&fine.image_b, &fine.coverage, 1, full, out_b, coverage);
        self.fine = fine;
        complete
    }

    /// A supersampled render's last step: `image` (`channels` per pixel, with
    /// its per-pixel `fine_coverage`, on the render grid) averaged block by
    /// block into `out` and `coverage` (resized) at the output size; returns
    /// how many output pixels all `full` frames cover ([`box_down`]).
    fn finish_fine(
        &self,
        image: &[u8],
        fine_coverage: &[u8],
        channels: usize,
        full: u8,
        out: &mut [u8],
        coverage: &mut Vec<u8>,
    ) -> usize {
        let (ow, oh) = (self.view_w, self.view_h);
        coverage.clear();
        coverage.resize(ow * oh, 0);
        box_down(
            image,
            fine_coverage,
            self.supersample,
            channels,
            (ow, oh),
            out,
            coverage,
            full,
        )
    }

    /// [`Warper::average_plane_pair_into`] on the render grid.
    #[allow(clippy::too_many_arguments)]
    fn render_plane_pair_into<'a, F: Fn(usize) -> (&'a [u8], &'a [u8])>(
        &mut self,
        planes_at: F,
        width: usize,
        height: usize,
        rotations: &[Matrix3<f64>],
        out_a: &mut [u8],
        out_b: &mut [u8],
        coverage: &mut Vec<u8>,
        fill: u8,
    ) -> usize {
        let (ow, oh) = (self.out.width, self.out.height);
        let n_frames = rotations.len().min(MAX_FRAMES);
        let mut datas: [[&[u8]; MAX_FRAMES]; 2] = [[&[]; MAX_FRAMES]; 2];
        for f in 0..n_frames {
            let (a, b) = planes_at(f);
            for (d, p) in datas.iter_mut().zip([a, b]) {
                if p.len() >= width * height {
                    d[f] = p;
                }
            }
        }
        let padded = |d: &[&[u8]]| d.iter().all(|p| p.len() >= width * height + FRAME_PADDING);
        let fused = self.deghost.filter(|_| n_frames > 1).is_none()
            && self.kernel.is_vectorized()
            && padded(&datas[0][..n_frames])
            && padded(&datas[1][..n_frames]);
        if !fused {
            let [a, b] = datas;
            let complete =
                self.render_plane_into(|i| a[i], width, height, rotations, out_a, coverage, fill);
            self.render_plane_into(|i| b[i], width, height, rotations, out_b, coverage, fill);
            return complete;
        }
        coverage.clear();
        coverage.resize(ow * oh, 0);
        let maps = self.prepare_maps(rotations);
        let full = rotations.len() as u8;
        let geom = Geometry::plane(width, height, 1);
        let pass_a = self.pass(&maps[..n_frames], &datas[0][..n_frames], geom, height);
        let pass_b = self.pass(&maps[..n_frames], &datas[1][..n_frames], geom, height);
        // The pair's rows side by side in one buffer, so that the rows can be
        // shared out among threads as one image; then copied to their planes.
        let mut rows = std::mem::take(&mut self.pair_rows);
        rows.resize(2 * ow * oh, 0);
        let complete = self.for_each_row(
            &mut rows,
            2 * ow,
            coverage,
            |w, scratch, v, out_row, cov_row| {
                scratch.fit(n_frames, ow, pass_a.tables, false);
                w.accumulate_row(&pass_a, Some(&pass_b), v, scratch, true);
                let (row_a, row_b) = out_row.split_at_mut(ow);
                let complete =
                    finish_gray_row(w.kernel, &pass_a, scratch, 0, row_a, cov_row, full, fill);
                finish_gray_row(w.kernel, &pass_b, scratch, 1, row_b, cov_row, full, fill);
                complete
            },
        );
        for ((pair, a), b) in rows
            .chunks_exact(2 * ow)
            .zip(out_a.chunks_exact_mut(ow))
            .zip(out_b.chunks_exact_mut(ow))
        {
            a.copy_from_slice(&pair[..ow]);
            b.copy_from_slice(&pair[ow..]);
        }
        self.pair_rows = rows;
        self.maps = maps;
        complete
    }

    /// Warps `frame` by `m` (output ray -> source ray) and calls
    /// `f(pixel_index, [r, g, b])` with 8.8 fixed-point samples for every
    /// pixel of the render grid ([`Warper::render_size`]: the output's, or the
    /// supersampled one) whose ray lands inside the source frame. Scalar: the
    /// reference the vectorized paths are tested against.
    pub fn warp<F: FnMut(usize, [u32; 3])>(
        &mut self,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        mut f: F,
    ) {
        if frame.width < 2 || frame.height < 2 {
            return;
        }
        let geom = Geometry::of(frame).with_cubic(self.cubic());
        let (ow, oh) = (self.out.width, self.out.height);
        let mut map = RowMap::default();
        let global = RollingProjector::default();
        self.prepare_map(&mut map, m, self.rows.first().unwrap_or(&global), None);
        let (mut xs, mut ys) = (vec![0f32; ow], vec![0f32; ow]);
        for v in 0..oh {
            self.fill_row(&map, v, &mut xs, &mut ys);
            for (u, (&sx, &sy)) in xs.iter().zip(&ys).enumerate() {
                if let Some(rgb) = geom.sample(frame.data, sx, sy) {
                    f(v * ow + u, rgb);
                }
            }
        }
    }

    /// Warps one interleaved frame into a saccade slot: 8.8 fixed-point samples
    /// (3 per pixel) and a coverage flag per pixel (0 where the frame does not
    /// cover it), the slot resized to this warper's output. Supersampled: each
    /// pixel is its block's [`box_down_slot`] (covered only where every sample is).
    pub fn warp_into_slot(
        &mut self,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        slot: &mut WarpedFrame,
        index: u64,
    ) {
        if self.supersample == 1 {
            return self.render_slot(frame, m, slot, index);
        }
        let (ow, oh) = (self.view_w, self.view_h);
        let mut fine = std::mem::take(&mut self.fine);
        self.render_slot(frame, m, &mut fine.slot, index);
        slot.index = index;
        slot.value.clear();
        slot.value.resize(3 * ow * oh, 0);
        slot.covered.clear();
        slot.covered.resize(ow * oh, 0);
        box_down_slot(
            &fine.slot.value,
            &fine.slot.covered,
            self.supersample,
            3,
            (ow, oh),
            &mut slot.value,
            &mut slot.covered,
        );
        self.fine = fine;
    }

    /// [`Warper::warp_into_slot`] on the render grid.
    fn render_slot(
        &mut self,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        slot: &mut WarpedFrame,
        index: u64,
    ) {
        let (ow, oh) = (self.out.width, self.out.height);
        slot.index = index;
        slot.value.clear();
        slot.value.resize(3 * ow * oh, 0);
        slot.covered.clear();
        slot.covered.resize(ow * oh, 0);
        let maps = self.prepare_maps(std::slice::from_ref(m));
        let datas = [frame.data];
        let pass = self.pass(&maps, &datas, Geometry::of(frame), frame.height);
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.fit(1, ow, pass.tables, false);
        for v in 0..oh {
            self.accumulate_row(&pass, None, v, &mut scratch, false);
            let vals = &mut slot.value[3 * v * ow..3 * (v + 1) * ow];
            let cov = &mut slot.covered[v * ow..(v + 1) * ow];
            let [r, g, b] = &scratch.sums;
            for u in 0..pass.n8 {
                vals[3 * u] = r[u] as u16;
                vals[3 * u + 1] = g[u] as u16;
                vals[3 * u + 2] = b[u] as u16;
                cov[u] = scratch.count[u] as u8;
            }
            for u in pass.n8..ow {
                if let Some(rgb) = pass
                    .geom
                    .sample(frame.data, scratch.xs[0][u], scratch.ys[0][u])
                {
                    vals[3 * u] = rgb[0] as u16;
                    vals[3 * u + 1] = rgb[1] as u16;
                    vals[3 * u + 2] = rgb[2] as u16;
                    cov[u] = 1;
                }
            }
        }
        self.scratch = scratch;
        self.maps = maps;
    }

    /// Warps one plane (`width x height`, followed by padding as for
    /// [`Warper::average_plane_into`]) into `values` (8.8 fixed-point samples)
    /// and `covered` (1 where the plane covers the output pixel), both this
    /// warper's output size; uncovered pixels get 0. Supersampled: as
    /// [`Warper::warp_into_slot`].
    pub fn warp_plane_into(
        &mut self,
        plane: &[u8],
        width: usize,
        height: usize,
        m: &Matrix3<f64>,
        values: &mut [u16],
        covered: &mut [u8],
    ) {
        if self.supersample == 1 {
            return self.render_plane_slot(plane, width, height, m, values, covered);
        }
        let view = (self.view_w, self.view_h);
        let mut fine = std::mem::take(&mut self.fine);
        let n = self.out.width * self.out.height;
        fine.slot.value.resize(n, 0);
        fine.slot.covered.resize(n, 0);
        self.render_plane_slot(
            plane,
            width,
            height,
            m,
            &mut fine.slot.value[..n],
            &mut fine.slot.covered[..n],
        );
        let s = self.supersample;
        box_down_slot(
            &fine.slot.value[..n],
            &fine.slot.covered[..n],
            s,
            1,
            view,
            values,
            covered,
        );
        self.fine = fine;
    }

    /// [`Warper::warp_plane_into`] on the render grid.
    fn render_plane_slot(
        &mut self,
        plane: &[u8],
        width: usize,
        height: usize,
        m: &Matrix3<f64>,
        values: &mut [u16],
        covered: &mut [u8],
    ) {
        let ow = self.out.width;
        let maps = self.prepare_maps(std::slice::from_ref(m));
        let datas = [plane];
        let pass = self.pass(&maps, &datas, Geometry::plane(width, height, 1), height);
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.fit(1, ow, pass.tables, false);
        for (v, (vals, cov)) in values
            .chunks_mut(ow)
            .zip(covered.chunks_mut(ow))
            .enumerate()
        {
            self.accumulate_row(&pass, None, v, &mut scratch, true);
            for u in 0..pass.n8 {
                vals[u] = scratch.sums[0][u] as u16;
                cov[u] = scratch.count[u] as u8;
            }
            for u in pass.n8..ow {
                let s = pass
                    .geom
                    .sample_gray(plane, scratch.xs[0][u], scratch.ys[0][u]);
                vals[u] = s.unwrap_or(0) as u16;
                cov[u] = s.is_some() as u8;
            }
        }
        self.scratch = scratch;
        self.maps = maps;
    }
}

/// Writes one interleaved output row from the kernel's sums (pixels `..n8`)
/// and the scalar path (the rest); returns the pixels every frame covers.
fn finish_rgb_row(
    kernel: Kernel,
    pass: &Pass<'_, '_>,
    scratch: &RowScratch,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    channels: usize,
    full: u8,
) -> usize {
    let (n8, ow) = (pass.n8, cov_row.len());
    let [r, g, b] = &scratch.sums;
    let n = &scratch.count;
    let mut complete = 0usize;
    // Kernels with a finishing pass (wasm simd128) finish RGBA rows in one go.
    // SAFETY: the row sums hold `ow >= n8` values, `out_row` `4 ow` bytes.
    let finished =
        channels == 4 && n8 > 0 && unsafe { kernel.finish_row_rgba(r, g, b, n, out_row, n8) };
    if !finished {
        for (u, px) in out_row[..channels * n8]
            .chunks_exact_mut(channels)
            .enumerate()
        {
            px[0] = average(r[u], n[u]);
            px[1] = average(g[u], n[u]);
            px[2] = average(b[u], n[u]);
            if channels == 4 {
                px[3] = 255;
            }
        }
    }
    for u in 0..n8 {
        let c = n[u] as u8;
        cov_row[u] = c;
        complete += (c == full) as usize;
    }
    for u in n8..ow {
        let (mut acc, mut c) = ([0u32; 3], 0u32);
        for (f, data) in pass.datas.iter().enumerate() {
            if let Some(rgb) = pass.geom.sample(data, scratch.xs[f][u], scratch.ys[f][u]) {
                acc[0] += rgb[0];
                acc[1] += rgb[1];
                acc[2] += rgb[2];
                c += 1;
            }
        }
        let px = &mut out_row[u * channels..u * channels + channels];
        px[0] = average(acc[0], c);
        px[1] = average(acc[1], c);
        px[2] = average(acc[2], c);
        if channels == 4 {
            px[3] = 255;
        }
        cov_row[u] = c as u8;
        complete += (c as u8 == full) as usize;
    }
    complete
}

/// Writes one single-channel output row from the vector kernel's sums in
/// `scratch.sums[sums]` and the scalar reference past them (uncovered pixels
/// `fill`); returns the pixels every frame covers.
#[allow(clippy::too_many_arguments)]
fn finish_gray_row(
    kernel: Kernel,
    pass: &Pass<'_, '_>,
    scratch: &RowScratch,
    sums: usize,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    full: u8,
    fill: u8,
) -> usize {
    let (n8, ow) = (pass.n8, cov_row.len());
    let (sum, n) = (&scratch.sums[sums][..n8], &scratch.count[..n8]);
    // SAFETY: `n8 > 0` only with a vectorized kernel from `Kernel::detect`
    // (a multiple of 8), and every row buffer holds `ow >= n8` values.
    let finished =
        unsafe { kernel.finish_row_gray(sum, n, out_row, cov_row, n8, full as u32, fill) };
    let mut complete = match finished {
        Some(complete) => complete,
        None => {
            // Separate branch-free passes over equal-length slices: each vectorizes.
            for ((o, &s), &k) in out_row[..n8].iter_mut().zip(sum).zip(n) {
                let v = average(s, k);
                *o = if k == 0 { fill } else { v };
            }
            for (c, &k) in cov_row[..n8].iter_mut().zip(n) {
                *c = k as u8;
            }
            n.iter().filter(|&&k| k == full as u32).count()
        }
    };
    for u in n8..ow {
        let (mut acc, mut c) = (0u32, 0u32);
        for (f, data) in pass.datas.iter().enumerate() {
            if let Some(s) = pass
                .geom
                .sample_gray(data, scratch.xs[f][u], scratch.ys[f][u])
            {
                acc += s;
                c += 1;
            }
        }
        out_row[u] = if c == 0 { fill } else { average(acc, c) };
        cov_row[u] = c as u8;
        complete += (c as u8 == full) as usize;
    }
    complete
}

/// Writes one interleaved output row from [`Warper::merge_row`]'s weighted
/// sums (every pixel); returns the pixels every frame covers.
fn finish_merged_rgb_row(
    kernel: Kernel,
    scratch: &RowScratch,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    channels: usize,
    full: u8,
) -> usize {
    let ow = cov_row.len();
    let [r, g, b] = &scratch.sums;
    let (w, n) = (&scratch.weight, &scratch.count);
    // The RGBA finisher divides by its "count": here the weights' sum, which
    // is 0 exactly where no frame covers the pixel.
    let n4 = ow / 8 * 8;
    // SAFETY: the row sums hold `ow >= n4` values, `out_row` `4 ow` bytes.
    let finished =
        channels == 4 && n4 > 0 && unsafe { kernel.finish_row_rgba(r, g, b, w, out_row, n4) };
    let start = if finished { n4 } else { 0 };
    for (u, px) in out_row[..channels * ow]
        .chunks_exact_mut(channels)
        .enumerate()
        .skip(start)
    {
        px[0] = weighted_average(r[u], w[u], 0);
        px[1] = weighted_average(g[u], w[u], 0);
        px[2] = weighted_average(b[u], w[u], 0);
        if channels == 4 {
            px[3] = 255;
        }
    }
    let mut complete = 0usize;
    for (c, &k) in cov_row.iter_mut().zip(&n[..ow]) {
        *c = k as u8;
        complete += (*c == full) as usize;
    }
    complete
}

/// Writes one single-channel output row from [`Warper::merge_row`]'s weighted
/// sums (uncovered pixels `fill`); returns the pixels every frame covers.
fn finish_merged_gray_row(
    scratch: &RowScratch,
    out_row: &mut [u8],
    cov_row: &mut [u8],
    full: u8,
    fill: u8,
) -> usize {
    let ow = cov_row.len();
    let (sum, w, n) = (
        &scratch.sums[0][..ow],
        &scratch.weight[..ow],
        &scratch.count[..ow],
    );
    for ((o, &s), &k) in out_row[..ow].iter_mut().zip(sum).zip(w) {
        *o = weighted_average(s, k, fill);
    }
    for (c, &k) in cov_row.iter_mut().zip(n) {
        *c = k as u8;
    }
    n.iter().filter(|&&k| k == full as u32).count()
}

/// Averages each `s x s` block of a supersampled render (`src`: `s ow x s oh`
/// pixels of `channels` bytes, `src_cov` its covering frames per pixel) into
/// one pixel of `out` (`ow x oh`) and `cov`; returns the pixels covered by
/// `full` frames.
///
/// A pixel's coverage is its block's least (it counts as covered by a frame
/// only where every sample is); its value the rounded mean (`(sum + n / 2) /
/// n`, half up as the kernels' averages) of the samples that some frame
/// covers, so a pixel on the edge of the covered area is not darkened by
/// the fill of its uncovered samples; with none covered, of all samples
/// (each the fill). Integers only: the same bytes whatever the kernel.
#[allow(clippy::too_many_arguments)]
fn box_down(
    src: &[u8],
    src_cov: &[u8],
    s: usize,
    channels: usize,
    (ow, oh): (usize, usize),
    out: &mut [u8],
    cov: &mut [u8],
    full: u8,
) -> usize {
    let rw = s * ow;
    let all = (s * s) as u32;
    let row = |v: usize, out_row: &mut [u8], cov_row: &mut [u8]| {
        let mut complete = 0;
        for (u, (px, c_out)) in out_row
            .chunks_exact_mut(channels)
            .zip(cov_row.iter_mut())
            .enumerate()
        {
            let (mut least, mut n) = (u8::MAX, 0u32);
            let (mut sum_cov, mut sum_all) = ([0u32; 4], [0u32; 4]);
            for l in 0..s {
                let first = (s * v + l) * rw + s * u;
                for i in first..first + s {
                    let c = src_cov[i];
                    least = least.min(c);
                    let covered = (c > 0) as u32;
                    n += covered;
                    for ch in 0..channels {
                        let x = src[i * channels + ch] as u32;
                        sum_all[ch] += x;
                        sum_cov[ch] += x * covered;
                    }
                }
            }
            let (sum, n) = if n > 0 { (sum_cov, n) } else { (sum_all, all) };
            for (o, &t) in px.iter_mut().zip(&sum) {
                *o = ((t + n / 2) / n) as u8;
            }
            *c_out = least;
            complete += (least == full) as usize;
        }
        complete
    };
    by_rows(
        &mut out[..ow * oh * channels],
        &mut cov[..ow * oh],
        ow,
        channels,
        row,
    )
}

/// Averages each `s x s` block of a supersampled saccade slot (`values`:
/// 8.8 fixed-point samples, `channels` per pixel; `covered`: 0 or 1 per
/// pixel; `s ow x s oh` pixels) into one pixel of `out_values` / `out_covered`
/// (`ow x oh`): covered only where every sample is (the slot is added to the
/// running sum as a whole frame, and a partly covered pixel would mix in the
/// uncovered samples' zeros), with the rounded mean of its samples; 0 elsewhere.
fn box_down_slot(
    values: &[u16],
    covered: &[u8],
    s: usize,
    channels: usize,
    (ow, oh): (usize, usize),
    out_values: &mut [u16],
    out_covered: &mut [u8],
) {
    let rw = s * ow;
    let n = (s * s) as u32;
    let row = |v: usize, out_row: &mut [u16], cov_row: &mut [u8]| {
        for (u, (px, c_out)) in out_row
            .chunks_exact_mut(channels)
            .zip(cov_row.iter_mut())
            .enumerate()
        {
            let mut all = true;
            let mut sum = [0u32; 3];
            for l in 0..s {
                let first = (s * v + l) * rw + s * u;
                for i in first..first + s {
                    all &= covered[i] != 0;
                    for (ch, acc) in sum.iter_mut().enumerate().take(channels) {
                        *acc += values[i * channels + ch] as u32;
                    }
                }
            }
            for (o, &t) in px.iter_mut().zip(&sum) {
                *o = if all { ((t + n / 2) / n) as u16 } else { 0 };
            }
            *c_out = all as u8;
        }
        0
    };
    let (values, covered) = (
        &mut out_values[..ow * oh * channels],
        &mut out_covered[..ow * oh],
    );
    by_rows(values, covered, ow, channels, row);
}

/// Calls `row(v, out_row, coverage_row)` for the rows of an `ow`-wide image
/// of `channels` values per pixel and its coverage, and sums what it returns:
/// on the rayon pool with the `parallel` feature and more than one thread.
fn by_rows<T: Send>(
    out: &mut [T],
    coverage: &mut [u8],
    ow: usize,
    channels: usize,
    row: impl Fn(usize, &mut [T], &mut [u8]) -> usize + Sync,
) -> usize {
    if ow == 0 || channels == 0 {
        return 0;
    }
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        if rayon::current_num_threads() > 1 {
            return out
                .par_chunks_mut(ow * channels)
                .zip(coverage.par_chunks_mut(ow))
                .enumerate()
                .map(|(v, (o, c))| row(v, o, c))
                .sum();
        }
    }
    out.chunks_mut(ow * channels)
        .zip(coverage.chunks_mut(ow))
        .enumerate()
        .map(|(v, (o, c))| row(v, o, c))
        .sum()
}

// The scalar slot fill sits here rather than in `accumulator.rs` so that the
// accumulator stays a plain buffer below the warper (no warper <-> accumulator cycle).
impl WarpedFrame {
    /// Warps `frame` into this slot (reusing its buffers) with the scalar
    /// sampler: the reference [`Warper::warp_into_slot`] is tested against.
    pub fn fill(
        &mut self,
        warper: &mut Warper,
        frame: &FrameRef<'_>,
        m: &Matrix3<f64>,
        index: u64,
    ) {
        let (w, h) = warper.render_size();
        self.index = index;
        self.value.clear();
        self.value.resize(3 * w * h, 0);
        self.covered.clear();
        self.covered.resize(w * h, 0);
        let (value, covered) = (&mut self.value, &mut self.covered);
        warper.warp(frame, m, |i, rgb| {
            value[3 * i] = rgb[0] as u16;
            value[3 * i + 1] = rgb[1] as u16;
            value[3 * i + 2] = rgb[2] as u16;
            covered[i] = 1;
        });
        let s = warper.supersample();
        if s > 1 {
            let view = warper.output_size();
            let (mut value, mut covered) =
                (vec![0u16; 3 * view.0 * view.1], vec![0u8; view.0 * view.1]);
            box_down_slot(
                &self.value,
                &self.covered,
                s,
                3,
                view,
                &mut value,
                &mut covered,
            );
            self.value = value;
            self.covered = covered;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shutter::{project_rolling, IntraFrame};
    use crate::so3::{self, Tangent};

    /// Every grid node of a rolling-shutter map is the fixed point of the
    /// projection through the readout (within its tolerance), whichever row
    /// it started from: the left neighbours' extrapolation, or none at a
    /// row's start and next to nodes out of view.
    #[test]
    fn grid_nodes_are_the_rolling_fixed_point() {
        let cams = [
            CameraModel::pinhole_hfov(320, 180, 90.0).unwrap(),
            CameraModel::fisheye_hfov(320, 180, 150.0, [0.05, -0.01, 0.002, -0.0005]).unwrap(),
        ];
        let intra = IntraFrame {
            phi: Tangent::new(0.08, -0.12, 0.05),
            psi: Tangent::new(-0.02, 0.03, 0.01),
            chi: Tangent::new(0.01, -0.005, 0.004),
            xi: Tangent::new(-0.004, 0.002, 0.003),
        };
        for src in &cams {
            let out = CameraModel::pinhole_hfov(240, 136, 70.0).unwrap();
            let warper = Warper::new(src, &out);
            let mut rows = RollingProjector::default();
            rows.set(&intra, src.height);
            // A turn that takes part of the view out of the frame.
            let m: Matrix3<f64> = *so3::exp(&Tangent::new(0.1, 0.5, 0.2)).matrix();
            let mut map = RowMap::default();
            warper.prepare_map(&mut map, &m, &rows, None);
            assert!(map.gridded);
            let (mut inside, mut outside) = (0, 0);
            for (ray, node) in warper.grid_rays.iter().zip(&map.grid) {
                // (Past the sensor's first and last rows the table holds the
                // end rows' rotations, where the exact path extrapolates: only
                // nodes that land on the sensor are sampled.)
                let on_sensor = |p: &Vector2<f64>| {
                    (0.0..=(src.width - 1) as f64).contains(&p.x)
                        && (0.0..=(src.height - 1) as f64).contains(&p.y)
                };
                match project_rolling(src, &m, &intra, ray) {
                    Some(p) if !on_sensor(&p) => outside += 1,
                    Some(p) => {
                        let d = ((node[0] as f64 - p.x).powi(2) + (node[1] as f64 - p.y).powi(2))
                            .sqrt();
                        assert!(d < 1e-3, "node {node:?} vs fixed point {p}");
                        inside += 1;
                    }
                    None => {
                        assert!(node[0].is_nan(), "{node:?}");
                        outside += 1;
                    }
                }
            }
            // (The 150 deg fisheye sees every node; the pinhole loses some.)
            let lost = if src.is_pinhole() { 10 } else { 0 };
            assert!(
                inside > 100 && outside >= lost,
                "{inside} nodes on the sensor, {outside} not"
            );
            // Looked up in the frame's landing map instead: the same nodes
            // within the map's interpolation error wherever they land on
            // the sensor (0.01 px for this 8.7 deg turn across the readout,
            // more than 300 deg/s turns through 20 ms), and none made up
            // where the lens sees nothing.
            let mut landing = LandingGrid::default();
            landing.set(&rows, src);
            let mut looked_up = RowMap::default();
            warper.prepare_map(&mut looked_up, &m, &rows, Some(&landing));
            let on_sensor = |p: &[f32; 2]| {
                (0.0..=(src.width - 1) as f32).contains(&p[0])
                    && (0.0..=(src.height - 1) as f32).contains(&p[1])
            };
            let mut compared = 0;
            for (exact, node) in map.grid.iter().zip(&looked_up.grid) {
                assert_eq!(exact[0].is_nan(), node[0].is_nan());
                if on_sensor(exact) {
                    let d = (exact[0] - node[0]).hypot(exact[1] - node[1]);
                    assert!(d < 1e-2, "looked up {node:?} vs {exact:?}");
                    compared += 1;
                }
            }
            assert_eq!(compared, inside);
        }
    }

    /// A frame keeps its landing map while it stays in the averaging window
    /// (found again one place further on), gets one at its first averaged
    /// map, and a frame that arrives starts without one.
    #[test]
    fn landing_maps_follow_their_frames() {
        let src =
            CameraModel::fisheye_hfov(320, 180, 150.0, [0.05, -0.01, 0.002, -0.0005]).unwrap();
        let frames: Vec<RollingProjector> = (0..4)
            .map(|k| {
                let intra = IntraFrame {
                    phi: Tangent::new(0.02 * (k + 1) as f64, -0.01, 0.005),
                    ..IntraFrame::default()
                };
                let mut rows = RollingProjector::default();
                rows.set(&intra, src.height);
                rows
            })
            .collect();
        let identity = [Matrix3::identity(); 3];
        let out = CameraModel::pinhole_hfov(160, 90, 70.0).unwrap();
        let mut warper = Warper::new(&src, &out);
        let built = |w: &Warper| w.landing.iter().map(|g| !g.is_empty()).collect::<Vec<_>>();
        warper.set_readout_rows(&frames[..3]);
        assert_eq!(built(&warper), [false; 3]);
        warper.prepare_maps(&identity);
        assert_eq!(built(&warper), [true; 3]);
        let first = warper.landing[1].clone();
        // The window moves on by one frame: the two that stay keep theirs,
        // the new one has none until it is mapped.
        warper.set_readout_rows(&frames[1..4]);
        assert_eq!(warper.readout_rows(), &frames[1..4]);
        assert_eq!(built(&warper), [true, true, false]);
        let p = Vector2::new(150.0, 80.0);
        assert_eq!(warper.landing[0].land(&p), first.land(&p));
        warper.prepare_maps(&identity);
        assert_eq!(built(&warper), [true; 3]);
        // One frame alone (a saccade slot) gets none.
        warper.set_readout_rows(&frames[..1]);
        warper.prepare_maps(&identity[..1]);
        assert_eq!(built(&warper), [false]);
        // Nor do a global shutter's frames.
        warper.set_readout_rows(&[RollingProjector::default(), RollingProjector::default()]);
        warper.prepare_maps(&identity[..2]);
        assert_eq!(built(&warper), [false, false]);
    }
}
