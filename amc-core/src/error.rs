//! Errors of the core. Each variant carries the bad value and, where one exists,
//! the allowed range, so a caller can print one actionable line.

use thiserror::Error;

/// Every error the core reports. No input makes the core panic.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum AmcError {
    /// A numeric parameter is outside its allowed range.
    #[error("invalid {name}: {value} (allowed: {allowed})")]
    InvalidParameter {
        name: &'static str,
        value: String,
        allowed: &'static str,
    },
    #[error("frame is empty: {width}x{height}")]
    EmptyFrame { width: usize, height: usize },
    #[error("frame {width}x{height} is too large")]
    FrameTooLarge { width: usize, height: usize },
    #[error("frame buffer has {actual} bytes, expected {expected}")]
    BufferLength { expected: usize, actual: usize },
    #[error("frame size changed from {expected_w}x{expected_h} to {actual_w}x{actual_h}; every frame of a clip must have the same size")]
    FrameSizeChanged {
        expected_w: usize,
        expected_h: usize,
        actual_w: usize,
        actual_h: usize,
    },
    #[error(
        "timestamp {t} s is not after the previous frame's {prev} s; timestamps must increase"
    )]
    NonMonotonicTimestamp { t: f64, prev: f64 },
    #[error("timestamp {0} is not a finite number")]
    NonFiniteTimestamp(f64),
    #[error("frame is {width}x{height} but the lens model is calibrated for a different aspect ratio ({lens_w}x{lens_h})")]
    LensAspectMismatch {
        width: usize,
        height: usize,
        lens_w: usize,
        lens_h: usize,
    },
    #[error(transparent)]
    Camera(#[from] crate::camera::CameraError),
    #[error(transparent)]
    Lens(#[from] crate::lens::LensError),
    /// An option name that no [`crate::options::OPTIONS`] entry has.
    #[error("unknown option {name:?} (known: {known})")]
    UnknownOption { name: String, known: String },
    #[error("focal-length self-calibration needs at least {needed} frames, got {got}")]
    TooFewFrames { needed: usize, got: usize },
}

impl AmcError {
    /// Shorthand for [`AmcError::InvalidParameter`].
    pub fn invalid(
        name: &'static str,
        value: impl std::fmt::Display,
        allowed: &'static str,
    ) -> Self {
        AmcError::InvalidParameter {
            name,
            value: value.to_string(),
            allowed,
        }
    }
}

/// Checks `lo <= value <= hi` (and finiteness) for a parameter.
pub(crate) fn check_range(
    name: &'static str,
    value: f64,
    lo: f64,
    hi: f64,
    allowed: &'static str,
) -> Result<(), AmcError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(AmcError::invalid(name, value, allowed))
    }
}
