//! `amc synth`'s flags.

use super::common::{parse_band, parse_k4};
use clap::Args;
use std::path::PathBuf;

/// Render a shaky synthetic clip (PNG frames, gt.csv, lens.json) from an
/// equirectangular panorama.
#[derive(Args, Debug, Clone)]
pub struct SynthArgs {
    /// Equirectangular (2:1, full-sphere) panorama, PNG or JPEG.
    pub panorama: PathBuf,

    /// Output directory (must not exist, or be empty).
    #[arg(short, long, value_name = "DIR")]
    pub output: PathBuf,

    /// Horizontal field of view, degrees (of the fisheye with --fisheye).
    #[arg(
        long,
        default_value_t = 90.0,
        value_name = "DEG",
        allow_negative_numbers = true
    )]
    pub fov: f64,

    /// Render through a Kannala-Brandt (OpenCV fisheye) lens with these
    /// coefficients instead of a pinhole.
    #[arg(long, value_name = "K1,K2,K3,K4", value_parser = parse_k4, allow_hyphen_values = true)]
    pub fisheye: Option<[f64; 4]>,

    /// Frame width, pixels.
    #[arg(long, default_value_t = 320)]
    pub width: usize,

    /// Frame height, pixels.
    #[arg(long, default_value_t = 180)]
    pub height: usize,

    /// Frames per second.
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true)]
    pub fps: f64,

    /// Clip length, seconds.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub seconds: f64,

    /// RMS angular speed of the shake, deg/s.
    #[arg(
        long,
        default_value_t = 100.0,
        value_name = "DEG_PER_S",
        allow_negative_numbers = true
    )]
    pub shake_dps: f64,

    /// Frequency band of the shake, Hz.
    #[arg(long, default_value = "12,20", value_name = "LO,HI", value_parser = parse_band, allow_hyphen_values = true)]
    pub shake_band: (f64, f64),

    /// Seed of the shake trajectory.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,

    /// Constant yaw pan, deg/s (positive turns right).
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "DEG_PER_S",
        allow_negative_numbers = true
    )]
    pub pan_dps: f64,

    /// Rolling-shutter readout time (first to last row), ms; 0 = global
    /// shutter. gt.csv holds the mid-readout orientation (row v is exposed
    /// at t + readout (v/H - 1/2)); lens.json states the readout (readout_ms).
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "MS",
        allow_negative_numbers = true
    )]
    pub rolling_shutter_ms: f64,

    /// Anti-aliasing: N x N rays per output pixel.
    #[arg(long, default_value_t = 2, value_name = "N")]
    pub supersample: usize,
    /// Also write gyro.gcsv (Gyroflow's format): the clip's motion as an IMU
    /// records it, this many samples per second (0: no log).
    #[arg(long, default_value_t = 0.0, value_name = "HZ")]
    pub gyro_rate_hz: f64,
    /// Video time of the log's first sample, seconds (video = log + offset).
    #[arg(long, default_value_t = -2.0, allow_negative_numbers = true, value_name = "S")]
    pub gyro_offset_s: f64,
    /// The log's clock against the video's, parts per million.
    #[arg(
        long,
        default_value_t = 0.0,
        allow_negative_numbers = true,
        value_name = "PPM"
    )]
    pub gyro_drift_ppm: f64,
    /// The IMU's mounting: the rotation vector (radians) taking IMU vectors
    /// into the camera frame (x right, y down, z forward).
    #[arg(long, default_value = "0,0,0", value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub gyro_mount_rotvec: [f64; 3],
    /// The gyro's bias, rad/s in the IMU's axes.
    #[arg(long, default_value = "0,0,0", value_name = "X,Y,Z", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub gyro_bias: [f64; 3],
    /// White noise on each axis, rad/s (standard deviation).
    #[arg(long, default_value_t = 0.0, value_name = "RAD_S")]
    pub gyro_noise: f64,
    /// A glitch: from video time START for LEN seconds, AMP rad/s added to the x axis.
    #[arg(long, value_name = "START,LEN,AMP", value_parser = parse_vec3, allow_hyphen_values = true)]
    pub gyro_glitch: Option<[f64; 3]>,
}

impl SynthArgs {
    /// The library's settings.
    pub fn config(self) -> amc_eval::synth::SynthConfig {
        amc_eval::synth::SynthConfig {
            panorama: self.panorama,
            output: self.output,
            fov: self.fov,
            fisheye: self.fisheye,
            width: self.width,
            height: self.height,
            fps: self.fps,
            seconds: self.seconds,
            shake_dps: self.shake_dps,
            shake_band: self.shake_band,
            seed: self.seed,
            pan_dps: self.pan_dps,
            rolling_shutter_ms: self.rolling_shutter_ms,
            supersample: self.supersample,
            gyro: (self.gyro_rate_hz > 0.0).then(|| amc_eval::synth_gyro::GyroLogConfig {
                rate_hz: self.gyro_rate_hz,
                offset_s: self.gyro_offset_s,
                drift_ppm: self.gyro_drift_ppm,
                mount_rotvec: self.gyro_mount_rotvec,
                bias: self.gyro_bias,
                noise: self.gyro_noise,
                glitch: self.gyro_glitch.map(|g| (g[0], g[1], g[2])),
                ..Default::default()
            }),
        }
    }
}

/// `X,Y,Z`: three finite numbers.
fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{s:?}: {e}"))?;
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(format!("{s:?}: three finite numbers separated by commas")),
    }
}
