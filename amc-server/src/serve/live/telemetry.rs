//! The text message that follows each frame on `/live`, whatever its codec.

use serde::Serialize;

/// The telemetry text message sent after each frame.
#[derive(Serialize, Clone, Debug)]
pub(super) struct LiveTelemetry {
    pub frame: u64,
    pub t: f64,
    pub speed_est_dps: f64,
    pub speed_view_dps: f64,
    pub valid: f64,
    pub saccade: bool,
    /// From the frame's arrival (decoded by ffmpeg, or received from the
    /// publisher) to its stabilized JPEG or H.264 access unit being ready,
    /// milliseconds.
    pub latency_ms: f64,
    pub width: usize,
    pub height: usize,
    /// What the binary message before it holds: `jpeg` or `h264`.
    pub codec: &'static str,
    /// H.264 only: the access unit's number in the encoder's stream. A gap
    /// in it (not in `frame`: the encoder may leave a frame out when it
    /// falls behind) is pictures this viewer skipped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unit: Option<u64>,
}
