//! A log from a stream or from bytes, through telemetry-parser.

use crate::error::TelemetryError;
use crate::log::GyroLog;
use crate::mp4_guard::check_mp4_has_moov;
use crate::picture::picture_motion;
use amc_core::gyro::GyroSamples;
use nalgebra::Vector3;
use std::io::{Read, Seek};
use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

/// Reads the log in `stream` (`size` bytes; `name` is the file's name,
/// which some formats are told apart by) with telemetry-parser. `Ok(None)`:
/// a known format without gyroscope samples; `Err`: not a format it knows,
/// or one it cannot use. A parser that panics on a damaged file is an error
/// like any other where panics unwind (native builds); in wasm32 a panic
/// aborts the module instance, so the damage known to make it panic (an MP4
/// cut short, without its `moov`) is refused before it is called.
pub fn read_gyro_stream<R: Read + Seek>(
    stream: &mut R,
    size: usize,
    name: &Path,
) -> Result<Option<GyroLog>, TelemetryError> {
    // The stream is not used again after a panic, so its state does not matter.
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parse(stream, size, name)))
        .unwrap_or(Err(TelemetryError::Panicked))
}

/// [`read_gyro_stream`] over a whole file held in memory (the page's clip),
/// `file_name` its name.
pub fn read_gyro_bytes(bytes: &[u8], file_name: &str) -> Result<Option<GyroLog>, TelemetryError> {
    let mut cursor = std::io::Cursor::new(bytes);
    read_gyro_stream(&mut cursor, bytes.len(), Path::new(file_name))
}

fn parse<R: Read + Seek>(
    stream: &mut R,
    size: usize,
    name: &Path,
) -> Result<Option<GyroLog>, TelemetryError> {
    let parser = |e: std::io::Error| TelemetryError::Parser(e.to_string());
    check_mp4_has_moov(stream, size as u64).map_err(TelemetryError::Parser)?;
    let input = telemetry_parser::Input::from_stream(
        stream,
        size,
        name,
        |_| {},
        Arc::new(AtomicBool::new(false)),
    )
    .map_err(parser)?;
    let camera = match input.camera_model() {
        Some(model) => format!("{} ({model})", input.camera_type()),
        None => input.camera_type(),
    };
    let readout_ms = input
        .frame_readout_time()
        .filter(|ms| ms.is_finite() && *ms > 0.0 && *ms <= amc_core::shutter::MAX_READOUT_MS);
    // Stabilized in the camera (GoPro's IORI): the picture did not move as
    // the body did; its own orientation is the motion to sync and fuse.
    if let Some(samples) = picture_motion(&input)? {
        return Ok(Some(GyroLog::from_telemetry(
            format!("{camera}, the picture's orientation (stabilized in the camera: CORI x IORI)"),
            samples,
            true,
            readout_ms,
        )));
    }
    let imu = telemetry_parser::util::normalized_imu(&input, None).map_err(parser)?;
    let mut samples = GyroSamples::default();
    for s in &imu {
        let Some(g) = s.gyro else { continue };
        let t = s.timestamp_ms * 1e-3;
        // Repeated or out-of-order times (a log's seams) are dropped.
        if samples.t.last().is_some_and(|&l| t <= l) || !t.is_finite() {
            continue;
        }
        samples.t.push(t);
        // telemetry-parser gives deg/s.
        samples
            .w
            .push(Vector3::new(g[0], g[1], g[2]).map(f64::to_radians));
    }
    if samples.t.is_empty() {
        return Ok(None);
    }
    Ok(Some(GyroLog::from_telemetry(
        camera, samples, false, readout_ms,
    )))
}
