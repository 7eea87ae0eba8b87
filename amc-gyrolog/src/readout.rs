//! The rolling-shutter readout measured against a log, where the camera
//! records none: a readout pass over the clip's first frames (tracked with
//! the rolling-shutter model on and each frame's rotation within it
//! measured, [`amc_core::readout::ReadoutEstimator`]) is synchronized with
//! the log, and the readout is the interval over which the log turns as
//! each frame's rows did ([`amc_core::gyro::readout_from_gyro`]). Before the
//! first pass, so that it tracks with the readout.

use crate::error::GyroLogError;
use crate::log::GyroLog;
use crate::report::sync_log;
use amc_core::gyro::{readout_from_gyro, GyroTrack};
use amc_core::readout::{measured, ReadoutEstimate};
use amc_core::{so3, Telemetry};
use nalgebra::Vector3;

/// The readout of a readout pass's frames (`pass`: its telemetry) against
/// `log`; `Ok(None)` with too few frames the log covers. Errors: the log
/// does not fit these frames.
pub fn measure_readout(
    log: &GyroLog,
    pass: &[Telemetry],
) -> Result<Option<ReadoutEstimate>, GyroLogError> {
    let (t, rots): (Vec<f64>, Vec<_>) = pass
        .iter()
        .map(|s| (s.t, so3::exp(&Vector3::from(s.r_est))))
        .unzip();
    let (sync, _) = sync_log(log, &t, &rots)?;
    let track = GyroTrack::new(&log.samples, &sync);
    let mut gaps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_by(f64::total_cmp);
    let Some(&period) = gaps.get(gaps.len() / 2) else {
        return Ok(None);
    };
    Ok(readout_from_gyro(&track, &measured(pass), period))
}
