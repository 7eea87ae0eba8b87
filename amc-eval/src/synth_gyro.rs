//! `amc synth`'s gyro log: the clip's own motion as a flight controller or a
//! camera would record it, as Gyroflow's `.gcsv` (read back through
//! telemetry-parser like any camera's log), with the ground truth of
//! everything a sync must find: the clock offset and drift, the IMU's
//! mounting, its bias, its noise, its rate and a glitch.
//!
//! Sample `i` is taken at video time `offset + i / rate * (1 + drift)`, and
//! stamped with log time `i / rate` (the log's clock starts at 0): video time
//! = log time + `offset` at the first sample, and the offset grows by
//! `drift_ppm` microseconds per second. Its value is
//! `mount^T omega(t) + bias + noise`, `omega` the shake's body rate (camera
//! axes, mid-readout time as everywhere), plus the glitch where it is.

use amc_synth::Shake;
use nalgebra::Vector3;
use std::fmt::Write as _;

/// What the log records and how.
#[derive(Clone, Debug, PartialEq)]
pub struct GyroLogConfig {
    /// Samples per second.
    pub rate_hz: f64,
    /// Video time of the log's first sample (video = log + offset), seconds.
    pub offset_s: f64,
    /// The log's clock against the video's, parts per million.
    pub drift_ppm: f64,
    /// Rotation vector (radians) taking IMU vectors into the camera frame.
    pub mount_rotvec: [f64; 3],
    /// Added to every sample, rad/s (IMU axes).
    pub bias: [f64; 3],
    /// Standard deviation of white noise on each axis, rad/s.
    pub noise: f64,
    /// `(start, length, amplitude)`: from video time `start` for `length`
    /// seconds, `amplitude` rad/s added to the x axis (a spike).
    pub glitch: Option<(f64, f64, f64)>,
    /// Log seconds after the video's end.
    pub tail_s: f64,
}

impl Default for GyroLogConfig {
    fn default() -> Self {
        Self {
            rate_hz: 1000.0,
            offset_s: -2.0,
            drift_ppm: 0.0,
            mount_rotvec: [0.0; 3],
            bias: [0.0; 3],
            noise: 0.0,
            glitch: None,
            tail_s: 1.0,
        }
    }
}

/// A setting outside its range: the flag, and the value with what is allowed.
#[derive(Debug, thiserror::Error)]
#[error("{detail}")]
pub struct GyroLogInvalid {
    /// The setting's CLI flag without dashes.
    pub option: &'static str,
    /// The value, what is allowed.
    pub detail: String,
}

/// File name of the log in the clip's folder.
pub const GYRO_LOG: &str = "gyro.gcsv";

impl GyroLogConfig {
    /// Checks the settings (flag names as the CLI's).
    pub fn validate(&self) -> Result<(), GyroLogInvalid> {
        let bad = |option: &'static str, detail: String| Err(GyroLogInvalid { option, detail });
        if !(self.rate_hz.is_finite() && (50.0..=20_000.0).contains(&self.rate_hz)) {
            return bad(
                "gyro-rate-hz",
                format!(
                    "--gyro-rate-hz must be 50 to 20000 Hz, got {}",
                    self.rate_hz
                ),
            );
        }
        if !(self.offset_s.is_finite() && self.offset_s.abs() <= 3600.0) {
            return bad(
                "gyro-offset-s",
                format!(
                    "--gyro-offset-s must be within an hour, got {}",
                    self.offset_s
                ),
            );
        }
        if !(self.drift_ppm.is_finite() && self.drift_ppm.abs() <= 10_000.0) {
            return bad(
                "gyro-drift-ppm",
                format!(
                    "--gyro-drift-ppm must be within 10000 ppm, got {}",
                    self.drift_ppm
                ),
            );
        }
        if !(self.noise.is_finite() && (0.0..=10.0).contains(&self.noise)) {
            return bad(
                "gyro-noise",
                format!("--gyro-noise must be 0 to 10 rad/s, got {}", self.noise),
            );
        }
        if self
            .mount_rotvec
            .iter()
            .chain(&self.bias)
            .any(|v| !v.is_finite() || v.abs() > 10.0)
        {
            return bad(
                "gyro-mount-rotvec",
                "--gyro-mount-rotvec and --gyro-bias need three finite values within 10".into(),
            );
        }
        Ok(())
    }

    /// The `.gcsv` text for `seconds` of video of `shake`.
    pub fn gcsv(&self, shake: &Shake, seconds: f64) -> String {
        let mount = amc_core::so3::exp(&Vector3::from(self.mount_rotvec));
        let bias = Vector3::from(self.bias);
        let mut noise = Gaussian(0x9e37_79b9_7f4a_7c15);
        let mut out = String::from(
            "GYROFLOW IMU LOG\nversion,1.3\nid,amc-synth\nvendor,amc-synth\norientation,XYZ\ntscale,1\ngscale,1\nt,gx,gy,gz\n",
        );
        // From the first sample to the video's end and the tail.
        let span = (seconds + self.tail_s - self.offset_s.min(seconds)).max(0.0);
        let n = (span * self.rate_hz).ceil() as usize + 1;
        for i in 0..n {
            let log_t = i as f64 / self.rate_hz;
            let video_t = self.offset_s + log_t * (1.0 + self.drift_ppm * 1e-6);
            let mut w = mount.transpose() * shake.angular_velocity_at(video_t) + bias;
            w += Vector3::new(noise.next(), noise.next(), noise.next()) * self.noise;
            if let Some((start, len, amp)) = self.glitch {
                if (start..start + len).contains(&video_t) {
                    w.x += amp;
                }
            }
            let _ = writeln!(out, "{log_t:.6},{:.7},{:.7},{:.7}", w.x, w.y, w.z);
        }
        out
    }
}

/// Standard normal samples from a fixed seed (xorshift and Box-Muller).
struct Gaussian(u64);

impl Gaussian {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    fn next(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
    }
}
