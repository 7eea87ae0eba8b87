//! Command-line arguments: the only place clap lives. One file per
//! subcommand; each subcommand's struct converts into the library's plain
//! settings; the stabilizer's own options come from
//! [`crate::options::StabilizerFlags`], generated from the core's one
//! definition of each option.

mod access;
mod common;
mod compare;
mod demo;
mod eval;
mod keys;
mod serve;
mod stabilize;
mod synth;
#[cfg(test)]
mod tests;
mod worker;

pub use access::{AccessFlags, KeysFlags};
pub use common::{LensFlags, RunFlags};
pub use compare::CompareArgs;
pub use demo::DemoArgs;
pub use eval::EvalArgs;
pub use keys::{KeysArgs, KeysCommand};
pub use serve::{ClusterFlags, ServeArgs};
pub use stabilize::StabilizeArgs;
pub use synth::SynthArgs;
pub use worker::WorkerArgs;

use clap::{Parser, Subcommand};

/// Artificial Microsaccade Compensation: stable video from shaking cameras.
#[derive(Parser, Debug)]
#[command(name = "amc", version, about, long_about = None)]
pub struct Cli {
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Stabilize a video, a folder of images, or a .y4m file.
    Stabilize(StabilizeArgs),
    /// Run none / stabilize / saccade on a clip and print the paper's metrics.
    Eval(EvalArgs),
    /// Render a rotation-only shaking sequence from an equirectangular panorama.
    Synth(SynthArgs),
    /// Render a built-in shaky clip, stabilize it and say where the results are.
    Demo(DemoArgs),
    /// Run the HTTP service: REST stabilization, batch jobs, a live WebSocket feed, the web page.
    Serve(ServeArgs),
    /// Run the jobs of `amc serve --queue --store` replicas (any number of workers, anywhere).
    Worker(WorkerArgs),
    /// Compare our modes with ffmpeg's vid.stab and deshake: speed and quality, one report.
    Compare(CompareArgs),
    /// API keys for `amc serve --auth-keys` (`amc keys new TENANT ROLES`).
    Keys(KeysArgs),
}
