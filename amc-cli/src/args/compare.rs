//! `amc compare`'s flags.

use super::common::parse_size;
use super::LensFlags;
use crate::error::CliError;
use clap::Args;
use std::path::PathBuf;

/// Compare our stabilizer with ffmpeg's vid.stab and deshake on the same clips.
#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Clips: videos, image folders, or folders holding `lens.json` with the images
    /// (directly or in `frames/`) and optionally `gt.csv` (as `amc synth` writes).
    pub clips: Vec<PathBuf>,
    /// Folder for the report (`README.md`, plots, `results.json`); created if missing.
    #[arg(long, value_name = "DIR")]
    pub report: PathBuf,
    /// Also render and compare the synthetic flapping-wing sequences (12-20 Hz shake,
    /// 100 and 300 deg/s, pinhole and fisheye, with and without rolling shutter).
    #[arg(long)]
    pub synthetic: bool,
    /// Length of each synthetic sequence, seconds (0.5..=60).
    #[arg(long, default_value_t = 5.0)]
    pub synthetic_seconds: f64,
    /// Size of the synthetic sequences, WxH.
    #[arg(long, default_value = "320x180", value_parser = parse_size)]
    pub synthetic_size: (usize, usize),
    /// Equirectangular panorama the synthetic sequences are rendered from.
    #[arg(long, default_value = "../shared/data/pano/pannellum_examplepano.jpg")]
    pub panorama: PathBuf,
    /// Lens of clips without a `lens.json` (default: --fov auto).
    #[command(flatten)]
    pub lens: LensFlags,
    /// Future frames of the `stabilize --lookahead` method (1..=300; default 30,
    /// as many as vid.stab's `smoothing=30` looks at on each side).
    #[arg(long, default_value_t = 30)]
    pub lookahead: usize,
    /// Frame rate of image folders without `gt.csv` timestamps (default 30).
    #[arg(long)]
    pub fps: Option<f64>,
    /// Longest any one child process (a method on a clip) may run, seconds.
    #[arg(long, default_value_t = 1800)]
    pub timeout: u64,
    /// Text describing the machine, added to the detected CPU and memory in the report.
    #[arg(long)]
    pub machine: Option<String>,
    /// Timed runs per method (1..=10); the fastest counts (least disturbed on a shared machine).
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
    /// Also write every method's per-frame measurements (`CLIP-frames.csv`).
    #[arg(long)]
    pub per_frame: bool,
    /// No progress messages.
    #[arg(short, long)]
    pub quiet: bool,
    /// Extra peers: `paper` runs the paper's own code (github.com/prgumd/AMC) in its
    /// three modes, and ours at its settings beside it; skipped (with a note in the
    /// report) when its environment is missing.
    #[arg(long, value_enum, value_name = "paper")]
    pub peer: Vec<ExtraPeer>,
    /// The paper's environment, made by tools/paper-peer/setup.sh (default:
    /// $AMC_PAPER_PEER, else ~/.cache/amc/paper-peer).
    #[arg(long, value_name = "DIR")]
    pub paper_env: Option<PathBuf>,
}

/// Peers `amc compare` runs only when asked.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExtraPeer {
    /// The paper's own implementation (Python/JAX).
    Paper,
}

impl CompareArgs {
    /// The library's settings.
    pub fn config(self) -> Result<amc_eval::compare::CompareConfig, CliError> {
        Ok(amc_eval::compare::CompareConfig {
            clips: self.clips,
            report: self.report,
            synthetic: self.synthetic,
            synthetic_seconds: self.synthetic_seconds,
            synthetic_size: self.synthetic_size,
            panorama: self.panorama,
            lens: self.lens.spec()?,
            lookahead: self.lookahead,
            fps: self.fps,
            timeout: self.timeout,
            machine: self.machine,
            repeat: self.repeat,
            per_frame: self.per_frame,
            quiet: self.quiet,
            paper_env: self.peer.contains(&ExtraPeer::Paper).then(|| {
                self.paper_env
                    .unwrap_or_else(amc_eval::compare::paper::default_env_dir)
            }),
        })
    }
}
