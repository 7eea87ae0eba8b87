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
        }
    }
}
