//! Parameters of the rolling-shutter model.

use crate::error::{check_range, AmcError};
use serde::{Deserialize, Serialize};

/// Longest readout accepted, milliseconds (a 10 frames/s sensor read out over
/// its whole frame period).
pub const MAX_READOUT_MS: f64 = 100.0;

/// The camera's shutter.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ShutterParams {
    /// Readout time (first row to last), milliseconds; 0 = global shutter
    /// (default). Phones and action cameras read out in 10-33 ms. With a
    /// readout, the tracker estimates each frame's motion during its readout
    /// and the renderer samples every source row at its own orientation.
    /// Range 0..=100.
    pub readout_ms: f64,
}

impl ShutterParams {
    /// Checks the readout against its range.
    pub fn validate(&self) -> Result<(), AmcError> {
        check_range(
            "readout_ms",
            self.readout_ms,
            0.0,
            MAX_READOUT_MS,
            "0..=100 milliseconds (0 = global shutter)",
        )
    }

    /// True when rows are exposed at different times.
    pub fn is_rolling(&self) -> bool {
        self.readout_ms > 0.0
    }

    /// Readout time in seconds.
    pub fn readout_s(&self) -> f64 {
        self.readout_ms / 1000.0
    }
}
