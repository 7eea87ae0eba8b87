//! Camera models: pinhole, OpenCV radial-tangential and OpenCV fisheye (Kannala-Brandt).
//!
//! Conventions: camera frame x right, y down, z forward; pixel centres at integer
//! coordinates (OpenCV), so the image spans `[-0.5, width - 0.5] x [-0.5, height - 0.5]`.
//!
//! Every model maps a ray `(X, Y, Z)` (any positive scale) to *distorted normalized
//! coordinates* `(xd, yd)` and then to pixels with the intrinsics (`skew` in pixels):
//! ```text
//! u = fx * xd + skew * yd + cx
//! v =            fy * yd + cy
//! ```
//!
//! One file per model, each with its equations, forward map, inverse and validity limit:
//! `pinhole.rs` ([`Distortion::None`]), `radtan.rs` ([`Distortion::RadTan`]) and
//! `fisheye.rs` ([`Distortion::Fisheye`]). `model.rs` holds [`CameraModel`] and its
//! model-independent methods; `poly.rs` the polynomial root finder behind the validity
//! limits and the inverses.

// Negated float comparisons (`!(x > 0.0)`) are deliberate throughout: they also reject NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod fisheye;
mod model;
mod pinhole;
mod poly;
mod radtan;
#[cfg(test)]
mod tests;

pub use model::{CameraError, CameraModel, Distortion};
