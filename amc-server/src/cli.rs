//! Command-line arguments. Every stabilizer option maps onto one field of
//! [`amc_core::StabilizerParams`], the definition shared with the REST and WASM APIs.

use amc_core::view::Mode;
use amc_core::StabilizerParams;
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

/// Artificial Microsaccade Compensation: stable video from shaking cameras.
#[derive(Parser, Debug)]
#[command(name = "amc", version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Stabilize a video, a folder of images, or a .y4m file.
    Stabilize(StabilizeArgs),
    /// Run none / stabilize / saccade on a clip and print the paper's metrics.
    Eval(EvalArgs),
    /// Render a rotation-only shaking sequence from an equirectangular panorama.
    Synth(crate::synth_cmd::SynthArgs),
    /// Render a built-in shaky clip, stabilize it and say where the results are.
    Demo(DemoArgs),
    /// Run the HTTP service: REST stabilization, batch jobs, a live WebSocket feed, the web page.
    Serve(crate::serve::ServeArgs),
    /// Compare our modes with ffmpeg's vid.stab and deshake: speed and quality, one report.
    Compare(crate::compare::CompareArgs),
}

/// How the lens is known.
#[derive(Args, Debug, Clone, Default)]
pub struct LensArgs {
    /// Lens file: the project's JSON, an OpenCV calibration (JSON/YAML) or a Gyroflow profile.
    #[arg(long, value_name = "FILE", conflicts_with = "fov")]
    pub lens: Option<PathBuf>,
    /// Horizontal field of view of a pinhole lens in degrees, or `auto` to estimate
    /// it from the footage. Default without --lens: auto.
    #[arg(long, value_name = "DEG|auto")]
    pub fov: Option<String>,
}

/// What `--lens`/`--fov` resolved to.
#[derive(Debug, Clone, PartialEq)]
pub enum LensChoice {
    File(PathBuf),
    Fov(f64),
    Auto,
}

impl LensArgs {
    pub fn choice(&self) -> Result<LensChoice, crate::error::CliError> {
        if let Some(p) = &self.lens {
            return Ok(LensChoice::File(p.clone()));
        }
        match self.fov.as_deref() {
            None => Ok(LensChoice::Auto),
            Some(s) if s.eq_ignore_ascii_case("auto") => Ok(LensChoice::Auto),
            Some(s) => match s.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 1.0 && v < 179.0 => Ok(LensChoice::Fov(v)),
                _ => Err(crate::error::CliError::Usage(format!(
                    "invalid --fov: {s} (allowed: a horizontal field of view in degrees, 1 < DEG < 179, or auto)"
                ))),
            },
        }
    }
}

/// Stabilizer options shared by `stabilize` and `eval`.
#[derive(Args, Debug, Clone)]
pub struct TuningArgs {
    /// Frames averaged into each output frame (1..=64).
    #[arg(long, default_value_t = 6)]
    pub n_avg: usize,
    /// Template reset period in frames (1..=1000).
    #[arg(long, default_value_t = 5)]
    pub n_track: usize,
    /// Share cropped from each side of the output (0..=0.45).
    #[arg(long, default_value_t = 0.125)]
    pub margin: f64,
    /// Width in pixels of the grayscale image the tracker works on (32..=8192).
    #[arg(long, default_value_t = 320)]
    pub track_width: usize,
    /// Future frames used to smooth the view (0 = online). Adds latency.
    #[arg(long, default_value_t = 0)]
    pub lookahead: usize,
    /// Output width in pixels (default: the cropped input width).
    #[arg(long)]
    pub output_width: Option<usize>,
    /// Output height in pixels (default: keeps the aspect ratio).
    #[arg(long)]
    pub output_height: Option<usize>,
    /// Frame rate to assume for image folders (default 30) or to override a video's timestamps.
    #[arg(long)]
    pub fps: Option<f64>,
    /// Longest time (seconds) an ffmpeg child may stall before it is killed.
    #[arg(long, default_value_t = 120)]
    pub timeout: u64,
}

impl TuningArgs {
    /// The stabilizer parameters for `mode`.
    pub fn params(&self, mode: Mode) -> StabilizerParams {
        let mut p = StabilizerParams::default();
        p.view.mode = mode;
        p.view.lookahead = self.lookahead;
        p.render.n_avg = self.n_avg;
        p.render.margin = self.margin;
        p.render.output_width = self.output_width;
        p.render.output_height = self.output_height;
        p.tracker.n_track = self.n_track;
        p.track_width = self.track_width;
        p
    }
}

#[derive(Args, Debug)]
pub struct StabilizeArgs {
    /// Input: any video ffmpeg reads, a folder of images (natural order), or .y4m.
    pub input: PathBuf,
    /// Output: .mp4 (H.264) / .webm / .mkv (audio copied), .y4m, or a folder for PNGs.
    #[arg(short, long)]
    pub output: PathBuf,
    /// stabilize (smooth view), saccade (fixed view, re-centred when needed) or none.
    #[arg(long, default_value = "stabilize", value_parser = parse_mode)]
    pub mode: Mode,
    #[command(flatten)]
    pub lens: LensArgs,
    #[command(flatten)]
    pub tuning: TuningArgs,
    /// Write per-frame telemetry (CSV: frame,t,rx,ry,rz,vx,vy,vz,...).
    #[arg(long, value_name = "FILE.csv")]
    pub telemetry: Option<PathBuf>,
    /// Write the clip's metrics (JSON).
    #[arg(long, value_name = "FILE.json")]
    pub metrics: Option<PathBuf>,
    /// Video quality (x264/VP9 CRF; lower is better).
    #[arg(long)]
    pub crf: Option<u8>,
    /// No progress bar or summary.
    #[arg(short, long)]
    pub quiet: bool,
}

#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Input clip (as for `stabilize`).
    pub input: PathBuf,
    #[command(flatten)]
    pub lens: LensArgs,
    #[command(flatten)]
    pub tuning: TuningArgs,
    /// Print JSON instead of a Markdown table.
    #[arg(long)]
    pub json: bool,
    /// Ground-truth orientations (`gt.csv` from `amc synth`): adds rotation errors.
    #[arg(long, value_name = "GT.csv")]
    pub gt: Option<PathBuf>,
    /// Write a per-frame plot (PNG) of angular speed and normal flow, like the paper's Figure 2.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
    /// No progress bar.
    #[arg(short, long)]
    pub quiet: bool,
}

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Folder for the demo's files.
    #[arg(short, long, default_value = "out/demo")]
    pub output: PathBuf,
    /// Equirectangular panorama to film (default: the shared Jordan Pond panorama
    /// if present, else a built-in procedural scene).
    #[arg(long)]
    pub panorama: Option<PathBuf>,
    /// RMS shake, deg/s.
    #[arg(long, default_value_t = 100.0)]
    pub shake_dps: f64,
    /// Clip length, seconds.
    #[arg(long, default_value_t = 5.0)]
    pub seconds: f64,
}

pub fn parse_mode(s: &str) -> Result<Mode, String> {
    s.parse::<Mode>().map_err(|e| e.to_string())
}
