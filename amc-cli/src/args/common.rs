//! Flags shared by several subcommands (input, lens, a run's options) and the
//! value parsers of the others.

use crate::error::CliError;
use crate::options::StabilizerFlags;
use amc_core::view::Mode;
use amc_core::LensSpec;
use clap::Args;
use std::path::PathBuf;

/// How the input is read.
#[derive(Args, Debug, Clone)]
pub struct InputFlags {
    /// Frame rate of an image folder (default: its meta.json or gt.csv, else 30),
    /// or to override a video's timestamps.
    #[arg(long)]
    pub fps: Option<f64>,
    /// Longest time (seconds) an ffmpeg child may stall before it is killed.
    #[arg(long, default_value_t = 120)]
    pub timeout: u64,
    /// Threads of a run: 1 decodes, stabilizes and encodes on one thread; 2 or
    /// more decode and encode on threads of their own, track each frame while
    /// the previous one renders, and render rows on N threads; same output
    /// (1..=256; default: every core).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=256))]
    pub threads: Option<u16>,
}

impl InputFlags {
    /// `--threads`, or every core.
    pub fn threads(&self) -> usize {
        self.threads
            .map_or_else(amc_engine::default_threads, usize::from)
    }
}

/// What every run over a clip takes: the lens file, the stabilizer's options
/// (with `--fov`) and how the input is read.
#[derive(Args, Debug)]
pub struct RunFlags {
    /// Lens file: the project's JSON, an OpenCV calibration (JSON/YAML) or a Gyroflow profile.
    #[arg(long, value_name = "FILE", conflicts_with = "fov")]
    pub lens: Option<PathBuf>,
    /// The stabilizer's options.
    #[command(flatten)]
    pub stabilizer: StabilizerFlags,
    /// How the input is read.
    #[command(flatten)]
    pub input: InputFlags,
}

/// How the lens of clips is known, for commands without the stabilizer's flags.
#[derive(Args, Debug, Clone, Default)]
pub struct LensFlags {
    /// Lens file: the project's JSON, an OpenCV calibration (JSON/YAML) or a Gyroflow profile.
    #[arg(long, value_name = "FILE", conflicts_with = "fov")]
    pub lens: Option<PathBuf>,
    /// Horizontal field of view of a pinhole lens in degrees (0 < DEG <= 179), or
    /// `auto` to estimate it from the footage. Default without --lens: auto.
    #[arg(long, value_name = "DEG|auto")]
    pub fov: Option<String>,
}

impl LensFlags {
    /// The lens these flags name.
    pub fn spec(&self) -> Result<LensSpec, CliError> {
        match (&self.lens, &self.fov) {
            (Some(p), _) => Ok(LensSpec::File(p.clone())),
            (None, Some(v)) => Ok(LensSpec::parse_fov(v)?),
            (None, None) => Ok(LensSpec::Auto),
        }
    }
}

/// Parses `stabilize`, `saccade` or `none`.
pub fn parse_mode(s: &str) -> Result<Mode, String> {
    s.parse::<Mode>().map_err(|e| e.to_string())
}

pub(super) fn parse_zoom(s: &str) -> Result<amc_core::Zoom, String> {
    s.parse::<amc_core::Zoom>().map_err(|e| e.to_string())
}

pub(super) fn parse_roll(s: &str) -> Result<amc_core::Roll, String> {
    s.parse::<amc_core::Roll>().map_err(|e| e.to_string())
}

pub(super) fn parse_floats<const N: usize>(s: &str, what: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} comma-separated numbers ({what}), got '{s}'"
        ));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(&parts) {
        *o = p
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| format!("'{p}' is not a finite number ({what})"))?;
    }
    Ok(out)
}

pub(super) fn parse_band(s: &str) -> Result<(f64, f64), String> {
    let [lo, hi] = parse_floats::<2>(s, "LO,HI in Hz")?;
    Ok((lo, hi))
}

pub(super) fn parse_k4(s: &str) -> Result<[f64; 4], String> {
    parse_floats::<4>(s, "K1,K2,K3,K4")
}

pub(super) fn parse_size(s: &str) -> Result<(usize, usize), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("'{s}' is not WxH"))?;
    let p = |v: &str| {
        v.trim()
            .parse::<usize>()
            .ok()
            .filter(|&n| (32..=4096).contains(&n))
            .ok_or_else(|| format!("'{v}' in '{s}' is not a size (allowed: 32..=4096 pixels)"))
    };
    Ok((p(w)?, p(h)?))
}
