//! `amc demo`'s flags.

use clap::Args;
use std::path::PathBuf;

/// `amc demo`.
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

impl DemoArgs {
    /// The library's settings.
    pub fn config(self) -> amc_eval::demo::DemoConfig {
        amc_eval::demo::DemoConfig {
            output: self.output,
            panorama: self.panorama,
            shake_dps: self.shake_dps,
            seconds: self.seconds,
        }
    }
}
