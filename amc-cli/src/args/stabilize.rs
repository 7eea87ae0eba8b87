//! `amc stabilize`'s flags.

use super::RunFlags;
use clap::Args;
use std::path::PathBuf;

/// `amc stabilize`.
#[derive(Args, Debug)]
pub struct StabilizeArgs {
    /// Input: any video ffmpeg reads, a folder of images (natural order), or .y4m.
    pub input: PathBuf,
    /// Output: .mp4 (H.264) / .webm / .mkv (audio copied), .y4m, or a folder for PNGs.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The lens, the stabilizer's options and how the input is read.
    #[command(flatten)]
    pub run: RunFlags,
    /// A folder of Gyroflow lens profiles (such as a clone of
    /// github.com/gyroflow/lens_profiles): the profile for the camera, lens
    /// mode and frame size the clip records is its lens, scaled to the
    /// clip, and named in one line and in --metrics ("lens_profile"); where
    /// none matches, the run goes on as without it (the field of view estimated).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["lens", "fov"])]
    pub lens_db: Option<PathBuf>,
    /// Write per-frame telemetry (CSV: frame,t,rx,ry,rz,vx,vy,vz,...).
    #[arg(long, value_name = "FILE.csv")]
    pub telemetry: Option<PathBuf>,
    /// The camera's gyro log: auto (the clip's own IMU track when it has one:
    /// GoPro, Sony, DJI, Insta360; else CLIP.gcsv beside it, or gyro.gcsv in
    /// a folder of frames), off, or a log file (Gyroflow .gcsv,
    /// Betaflight/ArduPilot logs, phone-app logs, or a CSV of a time column in
    /// seconds and three rates in rad/s). It is synchronized from the video
    /// itself (offset over the log's whole span, clock drift, mounting, bias,
    /// glitches), fused with the tracking (each frame's pose and rows from the
    /// gyro, held to the picture) and reported in one line and in --metrics ("gyro").
    #[arg(long, default_value = "auto", value_name = "auto|off|FILE")]
    pub gyro: amc_engine::gyro::GyroChoice,
    /// Write the clip's motion (fused, or from the video alone) as Gyroflow's
    /// .gcsv: the camera's body rate per frame interval in its axes (x right,
    /// y down, z forward), in video time, with the readout; a clip with no log
    /// can be finished in Gyroflow, or read back with --gyro.
    #[arg(long, value_name = "FILE.gcsv")]
    pub export_gcsv: Option<PathBuf>,
    /// Write the clip's metrics (JSON).
    #[arg(long, value_name = "FILE.json")]
    pub metrics: Option<PathBuf>,
    /// Video quality: x264 CRF 0..=51 for .mp4/.mkv (default 20), VP9 CRF 0..=63
    /// for .webm (default 32); lower is better and larger.
    #[arg(long, value_parser = clap::value_parser!(u8).range(0..=63))]
    pub crf: Option<u8>,
    /// x264 preset for .mp4/.mkv: ultrafast, superfast, veryfast (default),
    /// faster, fast, medium, slow, slower or veryslow; faster presets leave
    /// more of the CPU to the stabilizer and write larger files
    /// (docs/speed.md, the encoder's share).
    #[arg(long, value_name = "PRESET")]
    pub preset: Option<amc_video::X264Preset>,
    /// No progress bar or summary.
    #[arg(short, long)]
    pub quiet: bool,
}
