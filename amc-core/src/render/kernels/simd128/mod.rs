//! The WebAssembly `simd128` row kernels and row finishers (used when the
//! module is built with `+simd128`). Planes sampled bicubically take four
//! 32-bit lane loads a pixel, one per tap row (`sample_cubic_gray4`), and
//! interleaved frames sixteen, one per tap (`sample_cubic_rgb4`).
//!
//! One file per operation: `rgb.rs` (interleaved frames), `gray.rs` (planes),
//! `cubic.rs` (bicubic sampling of either), `finish.rs` (the row finishers);
//! `taps.rs` holds what they share (a row's coordinates, the bilinear taps,
//! the ghost-free weights).

mod cubic;
mod finish;
mod gray;
mod rgb;
mod taps;

pub(super) use finish::{finish_row_gray, finish_row_rgba};
pub(super) use gray::{accumulate_row_gray, accumulate_row_gray_pair, merge_row_gray};
pub(super) use rgb::{accumulate_row, merge_row};
