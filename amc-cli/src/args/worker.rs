//! `amc worker`'s flags.

use super::ClusterFlags;
use crate::error::CliError;
use clap::Args;
use std::net::SocketAddr;
use std::path::PathBuf;

/// `amc worker` options.
#[derive(Args, Debug, Clone)]
pub struct WorkerArgs {
    /// Address of the worker's /healthz and /metrics (port 0 picks a free port;
    /// the chosen one is printed).
    #[arg(long, default_value = "127.0.0.1:9090")]
    pub addr: SocketAddr,
    /// Folder for a job's files while it runs (default: the system's temp dir).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Threads of one job's run (1..=256; default: every core). One worker per
    /// machine with every core, or one single-threaded worker per core.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=256))]
    pub threads: Option<u16>,
    /// Longest a clip may take to process, seconds.
    #[arg(long, default_value_t = 3600)]
    pub job_time_limit: u64,
    /// How long a finished job's results are kept, seconds (the worker sweeps
    /// expired jobs, as the replicas do).
    #[arg(long, default_value_t = 3600)]
    pub job_ttl: u64,
    /// Longest an ffmpeg child may stall before it is killed, seconds.
    #[arg(long, default_value_t = 60)]
    pub ffmpeg_timeout: u64,
    /// This worker's name in the job table (default: host-pid-random).
    #[arg(long)]
    pub name: Option<String>,
    /// Log one JSON object per line (for log collectors) instead of text.
    #[arg(long)]
    pub log_json: bool,
    /// The shared job table and bucket (required).
    #[command(flatten)]
    pub cluster: ClusterFlags,
    /// Keys for /metrics (the replicas' --auth-keys file; needs admin).
    #[command(flatten)]
    pub keys: super::KeysFlags,
}

impl WorkerArgs {
    /// The library's settings.
    pub fn config(self) -> Result<amc_server::worker::WorkerConfig, CliError> {
        let cluster = self
            .cluster
            .config(self.job_ttl)?
            .ok_or(CliError::WorkerNeedsCluster)?;
        Ok(amc_server::worker::WorkerConfig {
            cluster,
            addr: self.addr,
            work_dir: self.work_dir,
            threads: self
                .threads
                .map_or_else(amc_engine::default_threads, usize::from),
            job_time_limit: self.job_time_limit,
            ffmpeg_timeout: self.ffmpeg_timeout,
            name: self.name,
            log_json: self.log_json,
            auth: self.keys.config(),
        })
    }
}
