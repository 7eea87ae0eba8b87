//! The command line's error: every subsystem's error, wrapped. `main` prints
//! it as one `error:` line and exits 1 (argument-syntax errors found by clap
//! exit 2, as clap does; an interrupting signal exits 128 + its number).

use amc_engine as engine;
use amc_eval::{compare, demo, eval, gt, synth};
use amc_server::serve;
use thiserror::Error;

/// Anything a command can fail with.
#[derive(Debug, Error)]
pub enum CliError {
    /// A run over a clip.
    #[error(transparent)]
    Run(#[from] engine::RunError),
    /// A gyro log that cannot be read (`--gyro FILE`).
    #[error(transparent)]
    Gyro(#[from] engine::gyro::GyroLogError),
    /// A lens database that cannot be read (`--lens-db DIR`).
    #[error(transparent)]
    LensDb(#[from] engine::lens_db::LensDbError),
    /// Video input or output outside a run (writing `--metrics`).
    #[error(transparent)]
    Video(#[from] amc_video::VideoError),
    /// An option refused by the core.
    #[error(transparent)]
    Core(#[from] amc_core::AmcError),
    /// `amc eval`.
    #[error(transparent)]
    Eval(#[from] eval::EvalError),
    /// `amc synth`.
    #[error(transparent)]
    Synth(#[from] synth::SynthError),
    /// `amc demo`.
    #[error(transparent)]
    Demo(#[from] demo::DemoError),
    /// `amc serve`.
    #[error(transparent)]
    Serve(#[from] serve::ServeError),
    /// `amc compare`.
    #[error(transparent)]
    Compare(#[from] compare::CompareError),
    /// `amc worker` and its job table.
    #[error(transparent)]
    Worker(#[from] amc_server::worker::WorkerError),
    /// The shared job table's or bucket's flags.
    #[error(transparent)]
    Cluster(#[from] amc_server::cluster::ClusterError),
    /// `amc worker` without the job table it works for.
    #[error("amc worker needs --queue postgres://... and --store s3://BUCKET (the same as the amc serve replicas')")]
    WorkerNeedsCluster,
    /// `amc keys new` with a bad tenant or role.
    #[error("{0}")]
    Keys(String),
    /// A ground-truth file.
    #[error(transparent)]
    Gt(#[from] gt::GtError),
}
