//! The rolling-shutter readout measured against a log, where the camera
//! records none: a readout pass over the clip's first frames (tracked with
//! the rolling-shutter model on and each frame's rotation within it
//! measured, [`amc_core::readout::ReadoutEstimator`]) is synchronized with
//! the log, and the readout is the interval over which the log turns as
//! each frame's rows did ([`amc_core::gyro::readout_from_gyro`]). Before the
//! first pass, so that it tracks with the readout.

use crate::error::GyroLogError;
use crate::fuse::sync_seen;
use crate::log::GyroLog;
use amc_core::gyro::{readout_from_gyro, GyroTrack};
use amc_core::readout::{frame_period, measured, ReadoutEstimate};
use amc_core::Telemetry;

/// The readout of a readout pass's frames (`pass`: its telemetry) against
/// `log`; `Ok(None)` with too few frames the log covers. Errors: the log
/// does not fit these frames.
pub fn measure_readout(
    log: &GyroLog,
    pass: &[Telemetry],
) -> Result<Option<ReadoutEstimate>, GyroLogError> {
    let (sync, _) = sync_seen(log, pass)?;
    let track = GyroTrack::new(&log.samples, &sync);
    let Some(period) = frame_period(pass) else {
        return Ok(None);
    };
    Ok(readout_from_gyro(&track, &measured(pass), period))
}
