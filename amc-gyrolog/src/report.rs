//! A log synchronized with a run's frames, and the report of it.

use crate::error::GyroLogError;
use crate::log::GyroLog;
use amc_core::gyro::{self, GyroSync, VisionStep};
use amc_core::readout::ReadoutEstimate;
use serde::Serialize;

/// The sync as `--metrics` reports it (`"gyro": {...}`).
#[derive(Clone, Debug, Serialize)]
pub struct GyroReport {
    /// What read the log ([`GyroLog::source`]).
    pub source: String,
    /// Its samples.
    pub samples: usize,
    /// Its sample rate.
    pub rate_hz: f64,
    /// Video time = log time + `offset_s`, at the clip's first frame.
    pub offset_s: f64,
    /// What log time counts from.
    pub log_time: &'static str,
    /// The log's clock against the video's, parts per million.
    pub drift_ppm: f64,
    /// Radians: the rotation taking IMU vectors into the camera frame.
    pub mount_rotvec: [f64; 3],
    /// Rad/s, IMU axes.
    pub bias_rad_s: [f64; 3],
    /// Intervals where the log disagrees with the picture.
    pub glitches: usize,
    /// RMS disagreement with the video, frame intervals other than glitches, rad/s.
    pub residual_rad_s: f64,
    /// Correlation of the log's and the video's angular speeds at the offset.
    pub correlation: f64,
    /// Frames whose pose and readout path came from the gyro, held to the
    /// picture (0 when the log was only synchronized, not fused).
    pub fused_frames: usize,
    /// Frame intervals where the gyro glitched and the picture bridged it.
    pub glitch_intervals_bridged: usize,
    /// Frames where tracking was lost, or disagreed with a sound log, that
    /// the gyro bridged.
    pub frames_bridged: usize,
    /// The readout measured against the log (`readout_ms=auto` where the
    /// camera records none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub readout: Option<ReadoutReport>,
}

/// The rolling-shutter readout as the log measured it.
#[derive(Clone, Debug, Serialize)]
pub struct ReadoutReport {
    /// Milliseconds (0: a global shutter).
    pub readout_ms: f64,
    /// Whether the clip pins it down (else the run keeps its own readout).
    pub confident: bool,
    /// Share of the rotation within frames the fit explains, 0..=1.
    pub explained: f64,
    /// Frames fitted.
    pub frames: usize,
}

impl From<&ReadoutEstimate> for ReadoutReport {
    fn from(r: &ReadoutEstimate) -> Self {
        Self {
            readout_ms: r.readout_ms,
            confident: r.confident,
            explained: r.explained,
            frames: r.frames,
        }
    }
}

impl GyroReport {
    /// One line for the terminal.
    pub fn line(&self) -> String {
        let m = self.mount_rotvec;
        let angle = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
            .sqrt()
            .to_degrees();
        format!(
            "gyro: {} ({} samples, {:.0} Hz): offset {:+.4} s (video = log + offset, log time from {}), drift {:+.0} ppm, mounting {angle:.1} deg (rotvec {:.4} {:.4} {:.4} rad), bias {:.4} {:.4} {:.4} rad/s, {} glitches, residual {:.3} rad/s; fused {} frames ({} glitch intervals bridged by the picture, {} frames by the gyro)",
            self.source,
            self.samples,
            self.rate_hz,
            self.offset_s,
            self.log_time,
            self.drift_ppm,
            m[0],
            m[1],
            m[2],
            self.bias_rad_s[0],
            self.bias_rad_s[1],
            self.bias_rad_s[2],
            self.glitches,
            self.residual_rad_s,
            self.fused_frames,
            self.glitch_intervals_bridged,
            self.frames_bridged,
        ) + &self.readout.as_ref().map_or(String::new(), |r| {
            format!(
                "; readout {:.1} ms measured against it ({:.0}% of the rotation within frames explained{})",
                r.readout_ms,
                100.0 * r.explained,
                if r.confident { "" } else { ", not pinned down: not used" }
            )
        })
    }
}

/// Synchronizes `log` with a run's frames (their times and estimated
/// orientations `R_{0,j}`).
pub fn sync_log(
    log: &GyroLog,
    t: &[f64],
    rots: &[amc_core::so3::Rot],
) -> Result<(GyroSync, GyroReport), GyroLogError> {
    let steps = VisionStep::from_orientations(t, rots);
    let synced = if log.video_clock {
        gyro::sync_at(&log.samples, &steps, 0.0)
    } else {
        gyro::sync(&log.samples, &steps)
    };
    let s: GyroSync = synced.map_err(|error| GyroLogError::Sync {
        source_name: log.source.clone(),
        error,
    })?;
    let m = s.mount_rotvec();
    let report = GyroReport {
        source: log.source.clone(),
        samples: log.samples.t.len(),
        rate_hz: log.samples.rate_hz(),
        offset_s: s.offset_s,
        log_time: log.time_base,
        drift_ppm: s.drift_ppm,
        mount_rotvec: [m.x, m.y, m.z],
        bias_rad_s: [s.bias.x, s.bias.y, s.bias.z],
        glitches: s.glitches,
        residual_rad_s: s.residual_rad_s,
        correlation: s.correlation,
        fused_frames: 0,
        glitch_intervals_bridged: 0,
        frames_bridged: 0,
        readout: None,
    };
    Ok((s, report))
}
