//! What `amc compare` is asked to do.

use amc_core::LensSpec;
use std::path::PathBuf;

/// Largest `--lookahead` accepted: the stabilizer's own limit.
pub const MAX_LOOKAHEAD: usize = amc_core::options::MAX_LOOKAHEAD;

/// Compare our stabilizer with ffmpeg's vid.stab and deshake on the same clips.
#[derive(Debug, Clone)]
pub struct CompareConfig {
    /// Clips: videos, image folders, or folders holding `lens.json` with the images
    /// (directly or in `frames/`) and optionally `gt.csv` (as `amc synth` writes).
    pub clips: Vec<PathBuf>,
    /// Folder for the report (`README.md`, plots, `results.json`); created if missing.
    pub report: PathBuf,
    /// Also render and compare the synthetic flapping-wing sequences (12-20 Hz shake,
    /// 100 and 300 deg/s, pinhole and fisheye, with and without rolling shutter).
    pub synthetic: bool,
    /// Length of each synthetic sequence, seconds (0.5..=60).
    pub synthetic_seconds: f64,
    /// Size of the synthetic sequences, WxH.
    pub synthetic_size: (usize, usize),
    /// Equirectangular panorama the synthetic sequences are rendered from.
    pub panorama: PathBuf,
    /// Lens of clips without a `lens.json` (default: --fov auto).
    pub lens: LensSpec,
    /// Future frames of the `stabilize --lookahead` method (1..=300).
    pub lookahead: usize,
    /// Frame rate of image folders without `gt.csv` timestamps (default 30).
    pub fps: Option<f64>,
    /// Longest any one child process (a method on a clip) may run, seconds.
    pub timeout: u64,
    /// Text describing the machine, added to the detected CPU and memory in the report.
    pub machine: Option<String>,
    /// Timed runs per method (1..=10); the fastest counts (least disturbed on a shared machine).
    pub repeat: usize,
    /// Also write every method's per-frame measurements (`CLIP-frames.csv`).
    pub per_frame: bool,
    /// No progress messages.
    pub quiet: bool,
    /// With `--peer paper`: the paper's environment made by
    /// `tools/paper-peer/setup.sh` (run beside ours when usable, else skipped).
    pub paper_env: Option<PathBuf>,
}
