//! The warper: maps output rows to source coordinates (an exact homography for
//! pinhole sources, an interpolated grid of the exact lens map otherwise) and
//! samples every frame there, through the row kernels.
//!
//! Interleaved frames (RGB, RGBA) are sampled three channels at a time; planar
//! frames one plane at a time, each plane by a warper whose cameras are that
//! plane's (the chroma planes of 4:2:0 frames by one built for the half-size
//! cameras, [`chroma_camera`]): one geometry, three planes.
//!
//! Supersampling (anti-aliasing of minified outputs, [`super::Antialias`]): a
//! warper built with `S > 1` ([`Warper::supersampled`]) renders every output
//! through the same kernels into a grid `S` times finer per axis, the output
//! camera rescaled pixel-centre correct (`f' = S f`, `c' = S c + (S - 1) / 2`:
//! fine pixel `S i + k` looks along the ray of output position `i + (k - (S -
//! 1) / 2) / S`, so the `S x S` samples of a pixel are spread evenly over it
//! around its centre), then averages each `S x S` block in integers
//! ([`box_down`](downsample::box_down),
//! [`box_down_slot`](downsample::box_down_slot)): the same bytes whatever the
//! kernel. With `S = 1` nothing of this runs and the output is the plain one.
//!
//! Output rows are independent. With the `parallel` feature, a frame's rows
//! are rendered in bands on the current rayon pool (each band with row buffers

mod average;
mod buffers;
mod chroma;
mod downsample;
mod finish;
mod map;
mod plane;
mod rows;
mod setters;
mod slot;
mod supersample;
#[cfg(test)]
mod tests;

use super::kernels::Kernel;
use super::params::Interpolation;
use super::robust::Deghost;
use crate::camera::CameraModel;
use crate::shutter::{LandingGrid, RollingProjector};
use buffers::{Fine, RowMap, RowScratch};
use nalgebra::{Matrix3, Vector3};

pub use chroma::chroma_camera;

/// Grid spacing (output pixels) of the exact lens map for distorted sources.
pub const GRID_STEP: usize = 8;

/// Grid spacing (output pixels) of a pinhole source's map through a rolling
/// shutter: the map is a homography bent smoothly by the readout motion, and
/// bilinear interpolation over 16 px cells stays within 0.005 px of it (see
/// `docs/core-history.md#render-rolling-grid-step`); a quarter of the nodes of
/// [`GRID_STEP`].
pub const ROLLING_GRID_STEP: usize = 16;

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
pub(super) const MAX_FRAMES: usize = 64;
