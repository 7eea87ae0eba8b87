//! Parameters of the renderer and the output camera they define.

use crate::camera::CameraModel;
use crate::error::{check_range, AmcError};
use serde::{Deserialize, Serialize};

/// Parameters of the renderer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderParams {
    /// Frames averaged into each output frame (`N_avg`; paper: 6). Range 1..=64.
    pub n_avg: usize,
    /// Share of the source width/height cropped from each side of the output
    /// with `zoom = none` (paper: 0.125, i.e. the central 75%); `auto` and
    /// `static` zoom instead. Range 0..=0.45.
    pub margin: f64,
    /// Output width in pixels; default: the cropped source width, rounded to even.
    /// Range 16..=16384.
    pub output_width: Option<usize>,
    /// Output height in pixels; default: keeps the cropped aspect ratio. Range 16..=16384.
    pub output_height: Option<usize>,
    /// Ghost-free averaging threshold, intensity levels of 255: each averaged
    /// frame's pixel counts fully where it differs from the newest frame's by
    /// at most this, not at all from twice this (so whatever moves in the
    /// scene comes from the newest frame only); 0 (the default) = the plain
    /// average. Range 0..=64 (see [`super::robust`]; 6 suits compressed video).
    pub deghost: f64,
}

impl Default for RenderParams {
    fn default() -> Self {
        Self {
            n_avg: 6,
            margin: 0.125,
            output_width: None,
            output_height: None,
            deghost: DEFAULT_DEGHOST,
        }
    }
}

/// Default ghost-free averaging threshold: 0, the plain average of the
/// paper. On real footage the plain average's smoothing of frame change
/// comes largely from blending what a rotation cannot align (parallax, the
/// rolling shutter): with `deghost` those pixels come from the newest frame,
/// sharp but unsmoothed (README, "Averaging without ghosts").
pub const DEFAULT_DEGHOST: f64 = 0.0;

/// A threshold that suits compressed 8-bit video: about 1-2 standard
/// deviations of the difference of two frames' noise, so the static scene
/// keeps most of the averaging's noise reduction.
pub const SUGGESTED_DEGHOST: f64 = 6.0;

impl RenderParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<(), AmcError> {
        if !(1..=64).contains(&self.n_avg) {
            return Err(AmcError::invalid("n_avg", self.n_avg, "1..=64 frames"));
        }
        check_range(
            "margin",
            self.margin,
            0.0,
            0.45,
            "0..=0.45 (share of each side)",
        )?;
        check_range(
            "deghost",
            self.deghost,
            0.0,
            super::robust::MAX_DEGHOST,
            "0..=64 intensity levels (0 = plain average)",
        )?;
        for (name, v) in [
            ("output_width", self.output_width),
            ("output_height", self.output_height),
        ] {
            if let Some(v) = v {
                if !(16..=16384).contains(&v) {
                    return Err(AmcError::invalid(name, v, "16..=16384 pixels"));
                }
            }
        }
        Ok(())
    }

    /// The ghost-free averaging weights; `None` for the plain average.
    pub fn deghost(&self) -> Option<super::Deghost> {
        super::Deghost::new(self.deghost)
    }

    /// The output camera for a source camera: a pinhole with the source's focal
    /// length (scaled when an explicit output size is asked for), centred,
    /// cropped by `margin`.
    pub fn output_camera(&self, src: &CameraModel) -> Result<CameraModel, AmcError> {
        self.output_camera_with_margin(src, self.margin)
    }

    /// [`RenderParams::output_camera`] cropped by `margin` (0..=0.45) instead
    /// of `self.margin`: the zoomed framings size the output at margin 0.
    pub fn output_camera_with_margin(
        &self,
        src: &CameraModel,
        margin: f64,
    ) -> Result<CameraModel, AmcError> {
        self.validate()?;
        let keep = 1.0 - 2.0 * margin.clamp(0.0, 0.45);
        let crop_w = src.width as f64 * keep;
        let crop_h = src.height as f64 * keep;
        let even = |x: f64| ((x / 2.0).round() as usize * 2).max(16);
        let (w, h) = match (self.output_width, self.output_height) {
            (None, None) => (even(crop_w), even(crop_h)),
            (Some(w), None) => (w, even(w as f64 * crop_h / crop_w)),
            (None, Some(h)) => (even(h as f64 * crop_w / crop_h), h),
            (Some(w), Some(h)) => (w, h),
        };
        // One scale for both axes, so rounding a size to even pixels crops
        // (or extends) by a fraction of a pixel instead of stretching the image;
        // only an explicit width *and* height may change the aspect ratio.
        let (sx, sy) = match (self.output_width, self.output_height) {
            (None, None) => (1.0, 1.0),
            (Some(_), None) => (w as f64 / crop_w, w as f64 / crop_w),
            (None, Some(_)) => (h as f64 / crop_h, h as f64 / crop_h),
            (Some(_), Some(_)) => (w as f64 / crop_w, h as f64 / crop_h),
        };
        Ok(CameraModel::pinhole(
            w,
            h,
            src.fx * sx,
            src.fy * sy,
            (w as f64 - 1.0) / 2.0,
            (h as f64 - 1.0) / 2.0,
        ))
    }
}
