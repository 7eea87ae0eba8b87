//! Rendering frames into the stable view.
//!
//! A pixel `p` of the output (a pinhole camera `K_out` looking along the view
//! `R^view_{0,j}`) shows the scene ray `x_out = K_out^-1 p`. In source frame `i`
//! (orientation `R_hat_{0,i}`) that ray is
//! ```text
//! x_i = R_hat_{0,i}^T R^view_{0,j} x_out = M x_out
//! ```
//! and is sampled at `project_i(x_i)` through the source lens, straight from the
//! original full-resolution frame (one bilinear or bicubic sample, [`Interpolation`]:
//! no intermediate images).
//! For a pinhole source the map is the homography `K_i M K_out^-1`, evaluated
//! exactly and incrementally along each row. For distorted lenses the exact map
//! is evaluated on a grid every [`GRID_STEP`] pixels and interpolated bilinearly
//! in between (the lens map is smooth: the interpolation error is far below a
//! pixel for real lenses, and this is ~20x cheaper than projecting every pixel).
//!
//! Samples are 8-bit fixed point (weights in 1/256), accumulated exactly in
//! integers, so the saccade mode's running sum can add and subtract frames
//! forever without drift.
//!
//! `params.rs` sizes the output view, `warper.rs` maps output rows to source
//! coordinates and samples them, `grid.rs` fills a row's coordinates from the
//! node grid of a gridded map, `accumulator.rs` holds the integer sums and the
//! saccade slots, `robust.rs` the ghost-free average (each frame weighted by
//! its agreement with the newest), `noise.rs` its automatic threshold, and `kernels/` the row kernels (scalar
//! reference, AVX2, `simd128`) behind one dispatcher. The warper uses the kernels and the accumulator (it
//! fills the saccade slots); neither uses the warper.

mod accumulator;
mod grid;
pub mod kernels;
pub mod noise;
mod params;
pub mod robust;
#[cfg(test)]
mod tests;
mod warper;

pub use accumulator::{Accumulator, WarpedFrame};
pub use noise::{noise_sigma, AutoDeghost};
pub use params::{
    footprint, Antialias, DeghostLevel, Interpolation, RenderParams, MAX_SUPERSAMPLE,
    SUGGESTED_DEGHOST, SUPERSAMPLE_ABOVE,
};
pub use robust::{Deghost, MAX_DEGHOST};
pub use warper::{chroma_camera, Warper, GRID_STEP};
