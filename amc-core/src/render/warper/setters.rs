//! Building a warper, and the settings of its renders.

use super::buffers::{Fine, RowScratch};
use super::{Warper, GRID_STEP, ROLLING_GRID_STEP};
use crate::camera::CameraModel;
use crate::render::kernels::Kernel;
use crate::render::params::{Interpolation, MAX_SUPERSAMPLE};
use crate::render::robust::Deghost;
use crate::shutter::RollingProjector;
use nalgebra::{Vector2, Vector3};

impl Warper {
    /// A warper from frames of `src` into `out` (a pinhole), one sample per
    /// output pixel.
    pub fn new(src: &CameraModel, out: &CameraModel) -> Self {
        Self::supersampled(src, out, 1)
    }

    /// A warper from frames of `src` into `out` (a pinhole) that averages
    /// `supersample x supersample` samples per output pixel (clamped to
    /// `1..=MAX_SUPERSAMPLE`; see the module's docs and
    /// [`crate::render::RenderParams::supersample`]). `S^2` times the sampling work.
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
    /// agreement with the last frame's (see [`crate::render::robust`]); `None` (the
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
    pub(super) fn cubic(&self) -> bool {
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
    /// A distorted source's frames each get a [`LandingGrid`](crate::shutter::LandingGrid) when they are
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
}
