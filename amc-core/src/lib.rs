//! # amc-core
//!
//! Artificial Microsaccade Compensation (AMC): rotation-only video stabilization.
//! Pure library: no I/O, no threads, no async; builds for `wasm32-unknown-unknown`.

pub mod camera;
pub mod error;
pub mod image;
pub mod lens;
pub mod so3;

pub use error::AmcError;
