//! What a lens file states, as [`parse_lens_file`](super::parse_lens_file) reads it.

use crate::camera::CameraModel;

/// What a lens file states: the camera, and the sensor's rolling-shutter
/// readout when the file gives one.
#[derive(Clone, Debug, PartialEq)]
pub struct LensFile {
    /// The camera model (validated).
    pub camera: CameraModel,
    /// Readout time (first row to last), milliseconds, in `0..=100`: the
    /// project JSON's `readout_ms`, a Gyroflow profile's `frame_readout_time`;
    /// `None` when the file does not say (OpenCV calibrations never do).
    pub readout_ms: Option<f64>,
}
