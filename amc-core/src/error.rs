//! Errors of the core. Each variant carries the bad value and, where one exists,
//! the allowed range, so a caller can print one actionable line.

use thiserror::Error;

/// Every error the core reports. No input makes the core panic.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum AmcError {
    /// A numeric parameter is outside its allowed range.
    #[error("invalid {name}: {value} (allowed: {allowed})")]
    InvalidParameter {
        /// Name of the parameter.
        name: &'static str,
        /// The offending value, formatted.
        value: String,
        /// Human-readable allowed range.
        allowed: &'static str,
    },
    /// A frame has no pixels.
    #[error("frame is empty: {width}x{height}")]
    EmptyFrame {
        /// Frame width, pixels.
        width: usize,
        /// Frame height, pixels.
        height: usize,
    },
    /// A frame is larger than 16384 pixels on a side.
    #[error("frame {width}x{height} is too large")]
    FrameTooLarge {
        /// Frame width, pixels.
        width: usize,
        /// Frame height, pixels.
        height: usize,
    },
    /// A frame buffer's length does not match its size and pixel format.
    #[error("frame buffer has {actual} bytes, expected {expected}")]
    BufferLength {
        /// [`crate::format::PixelFormat::buffer_len`] of the frame, bytes.
        expected: usize,
        /// Length of the buffer, bytes.
        actual: usize,
    },
    /// A frame's pixel format differs from the clip's first frame.
    #[error("pixel format changed from {expected:?} to {actual:?}; every frame of a clip must have the same format")]
    FormatChanged {
        /// The first frame's format.
        expected: crate::format::PixelFormat,
        /// This frame's format.
        actual: crate::format::PixelFormat,
    },
    /// A frame's size differs from the clip's first frame.
    #[error("frame size changed from {expected_w}x{expected_h} to {actual_w}x{actual_h}; every frame of a clip must have the same size")]
    FrameSizeChanged {
        /// Width of the clip's frames, pixels.
        expected_w: usize,
        /// Height of the clip's frames, pixels.
        expected_h: usize,
        /// Width of this frame, pixels.
        actual_w: usize,
        /// Height of this frame, pixels.
        actual_h: usize,
    },
    /// A timestamp is not after the previous frame's.
    #[error(
        "timestamp {t} s is not after the previous frame's {prev} s; timestamps must increase"
    )]
    NonMonotonicTimestamp {
        /// This frame's timestamp, seconds.
        t: f64,
        /// The previous frame's timestamp, seconds.
        prev: f64,
    },
    /// A timestamp (seconds) is NaN or infinite.
    #[error("timestamp {0} is not a finite number")]
    NonFiniteTimestamp(f64),
    /// The frames' aspect ratio differs (by more than 1%) from the lens calibration's.
    #[error("frame is {width}x{height} but the lens model is calibrated for a different aspect ratio ({lens_w}x{lens_h})")]
    LensAspectMismatch {
        /// Frame width, pixels.
        width: usize,
        /// Frame height, pixels.
        height: usize,
        /// Width the lens was calibrated at, pixels.
        lens_w: usize,
        /// Height the lens was calibrated at, pixels.
        lens_h: usize,
    },
    /// An invalid camera model.
    #[error(transparent)]
    Camera(#[from] crate::camera::CameraError),
    /// A lens file that could not be loaded.
    #[error(transparent)]
    Lens(#[from] crate::lens::LensError),
    /// An option name that no [`crate::options::OPTIONS`] entry has.
    #[error("unknown option {name:?} (known: {known})")]
    UnknownOption {
        /// The name given.
        name: String,
        /// The names there are.
        known: String,
    },
    /// Focal-length self-calibration got too few frames.
    #[error("focal-length self-calibration needs at least {needed} frames, got {got}")]
    TooFewFrames {
        /// Frames it needs.
        needed: usize,
        /// Frames it got.
        got: usize,
    },
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
pub fn check_range(
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
