//! Why a lens file could not be loaded.

use crate::camera::CameraError;
use thiserror::Error;

/// Why a lens file could not be loaded.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum LensError {
    /// The text is not valid JSON or YAML, or has no recognisable structure.
    #[error("lens file is not valid: {0}")]
    Parse(String),
    /// The content is valid JSON/YAML but matches none of the supported formats.
    #[error(
        "unrecognised lens file: expected the project format (keys model, width, height, fx, fy, cx, cy, dist), \
         an OpenCV calibration (camera_matrix, distortion_coefficients, image_width, image_height) \
         or a Gyroflow lens profile (calib_dimension, fisheye_params); found keys: {found}"
    )]
    UnknownFormat {
        /// The top-level keys that were found.
        found: String,
    },
    /// A required key is absent.
    #[error("{format} lens file is missing the key `{key}`")]
    MissingKey {
        /// Which format was detected.
        format: &'static str,
        /// Dotted path of the missing key.
        key: String,
    },
    /// A key is present but its value is wrong.
    #[error("`{key}` must be {expected}, found {found}")]
    InvalidValue {
        /// Dotted path of the key.
        key: String,
        /// What was expected.
        expected: String,
        /// The value that was found (abbreviated).
        found: String,
    },
    /// The file does not state the image size the calibration belongs to.
    #[error(
        "the lens file must state its image size (the resolution it was calibrated at): \
         add image_width and image_height, or image_size: [w, h]"
    )]
    MissingImageSize,
    /// The distortion model is not supported.
    #[error("unsupported distortion model in `{key}`: {found} (supported: {supported})")]
    UnsupportedModel {
        /// Dotted path of the key.
        key: String,
        /// The model that was found.
        found: String,
        /// The supported models.
        supported: &'static str,
    },
    /// The parameters were read but do not form a valid camera.
    #[error("lens parameters are invalid: {0}")]
    Camera(#[from] CameraError),
}
