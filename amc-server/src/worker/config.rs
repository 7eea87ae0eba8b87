//! `amc worker`'s settings ([`WorkerConfig`], checked into the service's
//! `Limits`) and its errors ([`WorkerError`]).

use crate::cluster::ClusterConfig;
use crate::serve::config::{check, ServiceError};
use crate::serve::Limits;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// `amc worker` settings (the command line's flags).
#[derive(Clone, Debug)]
pub struct WorkerConfig {
    /// The job table, the bucket and the lease (`--queue`, `--store`, ...).
    pub cluster: ClusterConfig,
    /// Address of `/healthz` and `/metrics` (port 0 picks a free port; the
    /// chosen one is printed).
    pub addr: SocketAddr,
    /// Folder for a job's local files while it runs (default: the system's
    /// temp dir); each job's folder is removed when it ends.
    pub work_dir: Option<PathBuf>,
    /// Threads of one job's run (1..=256).
    pub threads: usize,
    /// Longest a job may take to process, seconds (1..=604800).
    pub job_time_limit: u64,
    /// Longest an ffmpeg child may stall before it is killed, seconds (1..=86400).
    pub ffmpeg_timeout: u64,
    /// This worker's name in the job table (default: host, process id and
    /// a random suffix).
    pub name: Option<String>,
    /// Log one JSON object per line instead of text.
    pub log_json: bool,
    /// Keys for `/metrics` (`--auth-keys`, the replicas' file; `admin`).
    pub auth: crate::auth::AuthConfig,
}

/// Why a worker could not start or stopped with an error: a bad setting,
/// ffmpeg, the job table or the bucket, a folder, the socket or the runtime
/// (the failures it shares with `amc serve`).
pub type WorkerError = ServiceError;

impl WorkerConfig {
    /// Keys, or a loopback address, or `--insecure-no-auth` (as `amc serve`).
    pub(super) fn check_access(&self) -> Result<(), WorkerError> {
        self.auth.validate()?;
        if self.auth.keys_file.is_none()
            && !self.auth.insecure_no_auth
            && !self.addr.ip().is_loopback()
        {
            return Err(WorkerError::Unprotected { addr: self.addr });
        }
        Ok(())
    }

    pub(super) fn limits(&self) -> Result<Limits, WorkerError> {
        check("threads", self.threads, 1, 256)?;
        check("job-time-limit", self.job_time_limit, 1, 604_800)?;
        check("ffmpeg-timeout", self.ffmpeg_timeout, 1, 86_400)?;
        if let Some(name) = &self.name {
            let ok = (1..=64).contains(&name.len())
                && name
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b"-_.:".contains(&b));
            if !ok {
                return Err(WorkerError::Invalid {
                    flag: "name",
                    detail: format!(
                        "{name:?} (allowed: 1-64 of A-Z, a-z, 0-9, '-', '_', '.', ':')"
                    ),
                });
            }
        }
        self.cluster.validate()?;
        Ok(Limits {
            job_time_limit: Duration::from_secs(self.job_time_limit),
            ffmpeg_timeout: Duration::from_secs(self.ffmpeg_timeout),
            threads: self.threads,
            ..Limits::default()
        })
    }
}

/// A name no other worker has: host, process id, random suffix.
pub(super) fn default_name(host: &str) -> String {
    use rand::Rng;
    let suffix: u32 = rand::rngs::OsRng.gen();
    format!("{host}-{}-{:08x}", std::process::id(), suffix)
}
