//! The tracking front end: colour frame -> small undistorted grayscale pyramid.
//!
//! The frame is first box-averaged by an integer factor `s = floor(W / track_width)`
//! (exact area averaging, no aliasing), then, for a distorted lens, remapped to a
//! pinhole camera of the same focal length. A pinhole source needs no remap:
//! its downscaled camera is
//! ```text
//! f' = f / s,    c' = (c - (s - 1) / 2) / s
//! ```
//! because output pixel `u'` averages source pixels `s u' .. s u' + s - 1`.

use crate::camera::CameraModel;
use crate::error::AmcError;
use crate::image::{FrameRef, GrayImage};
use crate::pyramid::{luma_box_downscale_into, remap_into, Pyramid, RemapTable};
use nalgebra::Vector2;

/// Smallest tracking width (pixels): below this the coarse levels vanish.
pub const MIN_TRACK_WIDTH: usize = 32;

/// The camera after box-downscaling by `s` (see the module header).
pub fn box_downscaled(cam: &CameraModel, s: usize) -> CameraModel {
    let sf = s as f64;
    let off = (sf - 1.0) / 2.0;
    CameraModel {
        width: cam.width / s,
        height: cam.height / s,
        fx: cam.fx / sf,
        fy: cam.fy / sf,
        cx: (cam.cx - off) / sf,
        cy: (cam.cy - off) / sf,
        skew: cam.skew / sf,
        distortion: cam.distortion.clone(),
    }
}

/// Turns colour frames into tracker pyramids.
#[derive(Clone, Debug)]
pub struct TrackingFrontend {
    scale: usize,
    track_cam: CameraModel,
    remap: Option<RemapTable>,
    down: GrayImage,
}

impl TrackingFrontend {
    /// Front end for frames of `source` (a camera at the frames' resolution).
    pub fn new(source: &CameraModel, track_width: usize) -> Result<Self, AmcError> {
        if track_width < MIN_TRACK_WIDTH || track_width > 8192 {
            return Err(AmcError::invalid(
                "track_width",
                track_width,
                "32..=8192 pixels",
            ));
        }
        let scale = (source.width / track_width).max(1);
        let down = box_downscaled(source, scale);
        if down.width < MIN_TRACK_WIDTH || down.height < 16 {
            return Err(AmcError::invalid(
                "frame size",
                format!("{}x{}", source.width, source.height),
                "at least 32x16 pixels",
            ));
        }
        if source.is_pinhole() {
            return Ok(Self {
                scale,
                track_cam: down,
                remap: None,
                down: GrayImage::default(),
            });
        }
        let (w, h) = (down.width, down.height);
        let track_cam = CameraModel::pinhole(
            w,
            h,
            down.fx,
            down.fy,
            (w as f64 - 1.0) / 2.0,
            (h as f64 - 1.0) / 2.0,
        );
        let mut coords = Vec::with_capacity(w * h);
        for v in 0..h {
            for u in 0..w {
                let c = track_cam
                    .unproject(&Vector2::new(u as f64, v as f64))
                    .and_then(|ray| down.project(&ray))
                    .map_or([f32::NAN; 2], |p| [p.x as f32, p.y as f32]);
                coords.push(c);
            }
        }
        Ok(Self {
            scale,
            track_cam,
            remap: Some(RemapTable {
                width: w,
                height: h,
                coords,
            }),
            down: GrayImage::default(),
        })
    }

    /// The undistorted pinhole camera the tracker sees (finest level).
    pub fn camera(&self) -> &CameraModel {
        &self.track_cam
    }

    /// Fills `pyr` (with `levels` levels) from a colour frame.
    pub fn prepare(&mut self, frame: &FrameRef<'_>, pyr: &mut Pyramid, levels: usize) {
        if pyr.levels.is_empty() {
            pyr.levels.push(GrayImage::default());
        }
        match &self.remap {
            None => luma_box_downscale_into(frame, self.scale, &mut pyr.levels[0]),
            Some(table) => {
                luma_box_downscale_into(frame, self.scale, &mut self.down);
                remap_into(&self.down, table, &mut pyr.levels[0]);
            }
        }
        pyr.rebuild(levels);
    }
}
