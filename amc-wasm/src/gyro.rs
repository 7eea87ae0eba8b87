//! A clip's own gyro log for the page (`ClipGyro`): read from the clip's
//! bytes by telemetry-parser through amc-gyrolog, as the CLI's `--gyro auto`
//! reads it, or made again from its parts in another worker (the page parses
//! in a worker of its own, so that a parser that panics, which aborts a
//! wasm32 instance, takes only that worker down).

use crate::js::err;
use amc_core::gyro::GyroSamples;
use amc_gyrolog::{GyroLog, TelemetryError};
use nalgebra::Vector3;
use wasm_bindgen::prelude::*;

/// A clip's gyro log: where it came from, its samples.
#[wasm_bindgen]
pub struct ClipGyro {
    pub(crate) log: GyroLog,
}

#[wasm_bindgen]
impl ClipGyro {
    /// `ClipGyro.read(bytes, fileName)`: the log the clip's bytes hold (a
    /// GoPro's GPMF track, Sony, DJI, Insta360, or a log file), or `null`
    /// when there is none: a container telemetry-parser does not know (any
    /// phone's MP4), one without gyroscope samples. An `Error` when the clip
    /// holds a log that cannot be used (stabilized in the camera without the
    /// picture's orientation).
    pub fn read(bytes: &[u8], file_name: &str) -> Result<Option<ClipGyro>, JsError> {
        match amc_gyrolog::read_gyro_bytes(bytes, file_name) {
            Ok(log) => Ok(log.map(|log| ClipGyro { log })),
            // As the CLI's `auto`: no log it knows is no log.
            Err(TelemetryError::Parser(_)) => Ok(None),
            Err(e) => Err(err(e)),
        }
    }

    /// `ClipGyro.fromParts(source, videoClock, readoutMs, times, rates)`: a
    /// log read in another worker, from its [`ClipGyro::source`],
    /// [`ClipGyro::video_clock`], [`ClipGyro::readout_ms`],
    /// [`ClipGyro::times`] and [`ClipGyro::rates`]. Errors: `rates` not three
    /// per time.
    #[wasm_bindgen(js_name = fromParts)]
    pub fn from_parts(
        source: String,
        video_clock: bool,
        readout_ms: Option<f64>,
        times: Vec<f64>,
        rates: Vec<f64>,
    ) -> Result<ClipGyro, JsError> {
        if rates.len() != 3 * times.len() {
            return Err(JsError::new(&format!(
                "rates: {} values for {} times (expected three per time)",
                rates.len(),
                times.len()
            )));
        }
        let samples = GyroSamples {
            t: times,
            w: rates
                .chunks_exact(3)
                .map(|w| Vector3::new(w[0], w[1], w[2]))
                .collect(),
        };
        Ok(ClipGyro {
            log: GyroLog::from_telemetry(source, samples, video_clock, readout_ms),
        })
    }

    /// What read it: `"GoPro (HERO5 Black)"`.
    #[wasm_bindgen(getter)]
    pub fn source(&self) -> String {
        self.log.source.clone()
    }

    /// How many gyroscope samples it holds.
    #[wasm_bindgen(getter)]
    pub fn samples(&self) -> usize {
        self.log.samples.t.len()
    }

    /// Its sample rate, Hz.
    #[wasm_bindgen(getter, js_name = rateHz)]
    pub fn rate_hz(&self) -> f64 {
        self.log.samples.rate_hz()
    }

    /// The sensor's readout the clip records, milliseconds (`undefined`
    /// where it records none): the page's readout when it is `auto` or unset.
    #[wasm_bindgen(getter, js_name = readoutMs)]
    pub fn readout_ms(&self) -> Option<f64> {
        self.log.readout_ms
    }

    /// Whether its times are the video's own (a per-frame record, GoPro's
    /// image orientation): the offset is then not searched.
    #[wasm_bindgen(getter, js_name = videoClock)]
    pub fn video_clock(&self) -> bool {
        self.log.video_clock
    }

    /// The samples' times, seconds.
    pub fn times(&self) -> Vec<f64> {
        self.log.samples.t.clone()
    }

    /// The samples' rates, rad/s in the IMU's axes, x, y, z of each in turn.
    pub fn rates(&self) -> Vec<f64> {
        self.log
            .samples
            .w
            .iter()
            .flat_map(|w| [w.x, w.y, w.z])
            .collect()
    }
}
