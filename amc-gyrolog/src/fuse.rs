//! A log fused with a first pass's tracking: each frame's pose and readout
//! path, for [`amc_core::Stabilizer::push_posed`]. The first pass itself
//! (decoding, a stabilizer that does not render) is the caller's: ffmpeg in
//! the engine, WebCodecs in the page.

use crate::error::GyroLogError;
use crate::log::GyroLog;
use crate::report::{sync_log, GyroReport};
use amc_core::gyro::{fuse, FuseParams, FusedFrom, GyroSync, GyroTrack, VisionPose};
use amc_core::{so3, AmcError, GivenPose, Telemetry};
use nalgebra::Vector3;
use thiserror::Error;

/// Each frame's pose, and the report of the sync and the fusion.
#[derive(Clone, Debug)]
pub struct FusedLog {
    /// One per frame of the first pass, in order.
    pub poses: Vec<GivenPose>,
    /// The sync, with the fusion's counts.
    pub report: GyroReport,
}

/// Why a log is not fused.
#[derive(Debug, Error)]
pub enum FuseLogError {
    /// The log does not fit the video: the run goes on from the picture
    /// alone ([`video_only_warning`]).
    #[error(transparent)]
    Sync(#[from] GyroLogError),
    /// The fusion itself failed (its parameters).
    #[error(transparent)]
    Fuse(#[from] AmcError),
}

/// What a run says when the log does not fit and it goes on without it.
pub fn video_only_warning(e: &GyroLogError) -> String {
    format!("{e}; the output uses the video alone")
}

/// Synchronizes `log` with a first pass's frames (`seen`: the telemetry of
/// every output of a stabilizer fed the whole clip, with rendering off) and
/// fuses the two; `readout_s` is the sensor's readout the main pass runs with.
pub fn fuse_log(
    log: &GyroLog,
    seen: &[Telemetry],
    readout_s: f64,
) -> Result<FusedLog, FuseLogError> {
    let vision = vision_of(seen);
    let (sync, mut report) = sync_vision(log, &vision)?;
    let track = GyroTrack::new(&log.samples, &sync);
    let fusion = fuse(&track, &vision, readout_s, &FuseParams::default())?;
    report.fused_frames = fusion
        .frames
        .iter()
        .filter(|f| f.from == FusedFrom::Gyro)
        .count();
    report.glitch_intervals_bridged = fusion.glitch_intervals;
    report.frames_bridged = fusion.bridged_frames;
    let poses = fusion
        .frames
        .iter()
        .zip(seen)
        .map(|(f, s)| GivenPose {
            pose: f.pose,
            path: f.path,
            info: s.track,
        })
        .collect();
    Ok(FusedLog { poses, report })
}

/// A pass's telemetry as the picture's poses.
fn vision_of(seen: &[Telemetry]) -> Vec<VisionPose> {
    seen.iter()
        .map(|s| VisionPose {
            t: s.t,
            pose: so3::exp(&Vector3::from(s.r_est)),
            lost: s.track.lost,
        })
        .collect()
}

/// [`sync_log`] with the picture's poses.
fn sync_vision(
    log: &GyroLog,
    vision: &[VisionPose],
) -> Result<(GyroSync, GyroReport), GyroLogError> {
    let (t, rots): (Vec<f64>, Vec<_>) = vision.iter().map(|v| (v.t, v.pose)).unzip();
    sync_log(log, &t, &rots)
}

/// Synchronizes `log` with a pass's telemetry (`seen`).
pub(crate) fn sync_seen(
    log: &GyroLog,
    seen: &[Telemetry],
) -> Result<(GyroSync, GyroReport), GyroLogError> {
    sync_vision(log, &vision_of(seen))
}
