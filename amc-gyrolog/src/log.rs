//! A gyro log read in, with where it came from.

use amc_core::gyro::GyroSamples;

/// A log read in, with where it came from.
#[derive(Clone, Debug)]
pub struct GyroLog {
    /// What read it: `"GoPro (HERO5 Black)"`, `"gyro.txt (CSV)"`.
    pub source: String,
    /// How its times count: `"the log's first sample"` (telemetry-parser
    /// rebases them) or `"the log's own timestamps"` (a plain CSV).
    pub time_base: &'static str,
    /// The rates, rad/s, in the IMU's axes.
    pub samples: GyroSamples,
    /// The log's times are the video's (a camera's per-frame record, such
    /// as GoPro's image orientation): the offset is 0, not searched.
    pub video_clock: bool,
    /// The sensor's readout the clip records (GoPro's SROT, Sony, DJI,
    /// Insta360, a `.gcsv`'s `frame_readout_time`), milliseconds.
    pub readout_ms: Option<f64>,
}

impl GyroLog {
    /// A log as telemetry-parser gives it: its times from its first sample,
    /// or, with `video_clock`, the video's own (a per-frame record). Also the
    /// way a log read elsewhere (the page's parsing worker) is made again
    /// from its parts, with the same time base.
    pub fn from_telemetry(
        source: String,
        samples: GyroSamples,
        video_clock: bool,
        readout_ms: Option<f64>,
    ) -> Self {
        GyroLog {
            source,
            time_base: if video_clock {
                "the video's frames (the camera's per-frame record)"
            } else {
                "the log's first sample"
            },
            samples,
            video_clock,
            readout_ms,
        }
    }
}
