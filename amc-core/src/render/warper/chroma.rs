//! The camera of a 4:2:0 chroma plane.

use crate::camera::CameraModel;

/// The camera of a 4:2:0 chroma plane of frames seen through `cam`: half the
/// focal length, and chroma sample `u` at luma position `2 u + 0.5` (centred
/// siting), so `c' = (c - 0.5) / 2`; the size is the chroma plane's
/// (`ceil` of halves). Lens distortion acts on normalized coordinates and is kept.
pub fn chroma_camera(cam: &CameraModel) -> CameraModel {
    let (w, h) = crate::image::chroma_size(cam.width, cam.height);
    CameraModel {
        width: w,
        height: h,
        fx: cam.fx / 2.0,
        fy: cam.fy / 2.0,
        cx: (cam.cx - 0.5) / 2.0,
        cy: (cam.cy - 0.5) / 2.0,
        skew: cam.skew / 2.0,
        distortion: cam.distortion.clone(),
    }
}
