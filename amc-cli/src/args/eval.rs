//! `amc eval`'s flags.

use super::RunFlags;
use clap::Args;
use std::path::PathBuf;

/// `amc eval`.
#[derive(Args, Debug)]
pub struct EvalArgs {
    /// Input clip (as for `stabilize`).
    pub input: PathBuf,
    /// The lens, the stabilizer's options (`--mode` is ignored: every mode
    /// is run) and how the input is read.
    #[command(flatten)]
    pub run: RunFlags,
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
