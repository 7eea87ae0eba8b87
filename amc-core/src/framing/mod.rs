//! Framing: how much of the picture the output keeps, frame by frame, so that
//! it never shows a border.
//!
//! The output is a pinhole camera looking along the view. At zoom `z` its
//! focal length is `z` times the unzoomed output's (the source's focal length
//! at the output's scale), so it shows the central `1 / z` of the width and
//! height the unzoomed output would: `1 / z` is the kept share of the width.
//! An output ray of pixel `p` is `Z^-1 K_out^-1 p` with `Z = diag(z, z, 1)`, so
//! zooming is one more factor in the output -> source map the renderer
//! already applies: `M_i = R_hat_{0,i}^T R^view_{0,j} Z^-1` (no kernel changes).
//!
//! Per output frame `j` (see [`Framer`]):
//! 1. **need** (`coverage.rs`): the least zoom at which every output pixel is
//!    covered by at least one averaged frame (a pixel no frame covers would be
//!    shown black): rays through points spread along the output's border are
//!    followed from the centre outwards in each averaged frame; the border may
//!    reach no further than the farthest frame covers along any of them.
//! 2. **zoom** (`envelope.rs`): `auto` follows the need with a hold (the
//!    highest need of the last second), rises at most [`ZOOM_RISE_PER_S`] and
//!    falls at most [`ZOOM_FALL_PER_S`] per second (so it never pumps), and
//!    never above the crop budget `1 / (1 - max_crop)`; `static` holds one zoom
//!    for the whole clip (the highest need of a first pass, within the budget);
//!    `none` keeps today's fixed `margin`.
//! 3. **constraint** (`constrain.rs`): where the view needs more than the zoom
//!    allows, it is pulled toward the camera along the geodesic just far
//!    enough (bisection), so the budget and the no-border guarantee hold and
//!    the smoothing is kept everywhere else.

mod constrain;
mod coverage;
mod envelope;
mod params;
#[cfg(test)]
mod tests;

pub use constrain::pull_view;
pub use coverage::{needed_zoom, view_need, zoom_matrix, Border};
pub use envelope::{Framer, ZOOM_FALL_PER_S, ZOOM_HOLD_S, ZOOM_RISE_PER_S};
pub use params::{FramingParams, Zoom};
