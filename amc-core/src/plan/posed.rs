//! [`Pass::StaticZoom`](super::Pass::StaticZoom) for motion known before the
//! pass: a gyro fused with a first pass's tracking gives every frame's pose,
//! so the zoom needs no tracking and no pixels, only the view filter and the
//! framing over those poses.

use crate::camera::CameraModel;
use crate::error::AmcError;
use crate::image::{Frame, PixelFormat};
use crate::stabilizer::{GivenPose, Stabilizer, StabilizerParams};

/// The highest zoom any output needs when frames `width x height` have the
/// given `(t, pose)`s, in order: what the static-zoom pass finds, with these
/// poses in place of the tracker's. `None` when `params` need no such pass.
pub fn static_zoom_posed(
    camera: &CameraModel,
    width: usize,
    height: usize,
    params: &StabilizerParams,
    poses: impl IntoIterator<Item = (f64, GivenPose)>,
) -> Result<Option<f64>, AmcError> {
    if !params.wants_static_zoom() {
        return Ok(None);
    }
    let mut stab = Stabilizer::new(camera, width, height, params.clone())?;
    stab.set_rendering(false);
    // Not rendered, so never read: any frame of the right size stands in.
    let blank = Frame::new(width, height, PixelFormat::Yuv420p);
    for (t, pose) in poses {
        stab.push_posed(blank.as_ref(), t, pose)?;
    }
    while stab.finish().is_some() {}
    Ok(Some(stab.max_zoom_need()))
}
