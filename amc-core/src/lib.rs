//! # amc-core
//!
//! Artificial Microsaccade Compensation (AMC): rotation-only video stabilization.
//! Pure library: no I/O, no threads of its own, no async; builds for
//! `wasm32-unknown-unknown`. With the `parallel` feature the renderer splits
//! each frame's rows across the caller's rayon pool (same bytes as one thread).

#![deny(missing_docs)]

#[macro_use]
mod multiversion;

pub mod camera;
pub mod color;
pub mod error;
pub mod format;
pub mod framing;
pub mod image;
pub mod lanes;
pub mod lens;
pub mod so3;

pub use error::AmcError;
pub mod frontend;
pub mod gyro;
pub mod metrics;
pub mod minimize;
pub mod options;
pub mod plan;
pub mod pyramid;
pub mod readout;
pub mod render;
pub mod selfcal;
pub mod shutter;
pub mod stabilizer;
pub mod tracker;
pub mod view;

pub use camera::CameraModel;
pub use framing::Zoom;
pub use image::{Frame, FrameRef, PixelFormat};
pub use options::{LensSpec, ReadoutSpec, StabilizerOptions};
pub use stabilizer::{GivenPose, Stabilizer, StabilizerParams, Telemetry};
pub use view::{Mode, Roll};
