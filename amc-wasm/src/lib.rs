//! # amc-wasm
//!
//! Thin wasm-bindgen bindings over [`amc_core`] for the web page: a
//! [`Stabilizer`] built from the shared [`StabilizerParams`](amc_core::StabilizerParams) (JSON, the same
//! definition the CLI and the REST API use), fed frames with their timestamps,
//! returning the stabilized frame as a view into WASM memory and its telemetry
//! as a plain object.
//!
//! Frames are RGBA (the default), or planar 4:2:0 as WebCodecs decoders give
//! them: `"I420"` (Y, U, V planes) or `"NV12"` (Y plane, then interleaved UV,
//! de-interleaved here). Planar frames are rendered plane by plane with no
//! colour conversion and come out as I420 (see [`Stabilizer::new`]).
//!
//! A clip's own gyro log ([`ClipGyro`], read from its bytes as the CLI's
//! `--gyro auto` reads it) is synchronized and fused with a first pass's
//! tracking ([`GyroPass`]); the main stabilizer then renders each frame with
//! its fused pose ([`Stabilizer::set_poses`]).
//!
//! Every bad input (sizes, buffer lengths, timestamps, parameters, lens files)
//! becomes a JavaScript `Error` whose message names the value and the allowed
//! range; nothing here panics on user input.
//!
//! Views returned by [`Stabilizer::input_buffer`], [`Stabilizer::output`] and
//! [`Stabilizer::coverage`] alias WASM memory: they are valid until the next
//! call into the module (memory growth detaches them); copy what you keep.

pub mod args;
mod gyro;
mod gyro_pass;
mod input;
mod js;
mod kernels;
mod options;
mod plan;
mod readout;
mod stabilizer;

pub use gyro::ClipGyro;
pub use gyro_pass::GyroPass;
pub use kernels::{simd_enabled, simd_matches_scalar};
pub use options::{options, resolve_options};
pub use plan::PassPlan;
pub use readout::ReadoutEstimator;
pub use stabilizer::Stabilizer;
