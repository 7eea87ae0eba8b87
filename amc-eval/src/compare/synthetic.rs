//! The synthetic test sequences of the comparison: flapping-wing shake
//! (12-20 Hz band, 100 and 300 deg/s RMS, 60 fps) rendered from the
//! panorama through a pinhole (90 deg) and a Kannala-Brandt fisheye
//! (150 deg), with a global shutter and with a rolling shutter, by the same
//! code as `amc synth`.

use super::config::CompareConfig;
use super::error::CompareError;
use crate::synth::{self, SynthConfig};
use std::path::{Path, PathBuf};

/// Frame rate of the synthetic sequences.
pub const FPS: f64 = 60.0;
/// Shake band, Hz.
pub const BAND_HZ: (f64, f64) = (12.0, 20.0);
/// Fisheye coefficients (as in the ground-truth tests).
pub const FISHEYE_K: [f64; 4] = [0.05, -0.01, 0.002, -0.0005];
/// Rolling-shutter readout time, ms (first to last row).
pub const READOUT_MS: f64 = 10.0;

/// One synthetic sequence.
#[derive(Clone, Copy, Debug)]
pub struct Sequence {
    pub name: &'static str,
    pub fisheye: bool,
    pub shake_dps: f64,
    pub rolling_shutter: bool,
    pub seed: u64,
}

/// Every sequence `--synthetic` compares.
pub const SEQUENCES: [Sequence; 8] = {
    const fn s(name: &'static str, fisheye: bool, shake_dps: f64, rs: bool) -> Sequence {
        Sequence {
            name,
            fisheye,
            shake_dps,
            rolling_shutter: rs,
            seed: 3,
        }
    }
    [
        s("synth-pinhole-100", false, 100.0, false),
        s("synth-pinhole-300", false, 300.0, false),
        s("synth-pinhole-100-rs", false, 100.0, true),
        s("synth-pinhole-300-rs", false, 300.0, true),
        s("synth-fisheye-100", true, 100.0, false),
        s("synth-fisheye-300", true, 300.0, false),
        s("synth-fisheye-100-rs", true, 100.0, true),
        s("synth-fisheye-300-rs", true, 300.0, true),
    ]
};

impl Sequence {
    /// One line for the report.
    pub fn describe(&self, args: &CompareConfig) -> String {
        format!(
            "synthetic: {} {} deg, {}x{}, {} fps, {} s, {}-{} Hz shake at {} deg/s RMS (seed {}), {}",
            if self.fisheye { "fisheye (Kannala-Brandt)" } else { "pinhole" },
            if self.fisheye { 150 } else { 90 },
            args.synthetic_size.0,
            args.synthetic_size.1,
            FPS,
            args.synthetic_seconds,
            BAND_HZ.0,
            BAND_HZ.1,
            self.shake_dps,
            self.seed,
            if self.rolling_shutter {
                format!(
                    "rolling shutter ({READOUT_MS} ms readout; cropping and distortion measured \
                     against its global-shutter twin)"
                )
            } else {
                "global shutter".to_string()
            }
        )
    }
}

/// Renders `seq` into `work/<name>-src` and returns that folder, and for a
/// rolling-shutter sequence its global-shutter twin (the same motion, each
/// frame at its mid-readout pose) in `work/<name>-gs`.
pub fn render(
    seq: &Sequence,
    args: &CompareConfig,
    work: &Path,
) -> Result<(PathBuf, Option<PathBuf>), CompareError> {
    let out = work.join(format!("{}-src", seq.name));
    let mut synth = SynthConfig {
        panorama: args.panorama.clone(),
        output: out.clone(),
        fov: if seq.fisheye { 150.0 } else { 90.0 },
        fisheye: seq.fisheye.then_some(FISHEYE_K),
        width: args.synthetic_size.0,
        height: args.synthetic_size.1,
        fps: FPS,
        seconds: args.synthetic_seconds,
        shake_dps: seq.shake_dps,
        shake_band: BAND_HZ,
        seed: seq.seed,
        pan_dps: 0.0,
        rolling_shutter_ms: if seq.rolling_shutter { READOUT_MS } else { 0.0 },
        supersample: 2,
        gyro: None,
    };
    synth::run(&synth, &|_, _| {})?;
    if !seq.rolling_shutter {
        return Ok((out, None));
    }
    let twin = work.join(format!("{}-gs", seq.name));
    synth.output = twin.clone();
    synth.rolling_shutter_ms = 0.0;
    synth::run(&synth, &|_, _| {})?;
    Ok((out, Some(twin)))
}
