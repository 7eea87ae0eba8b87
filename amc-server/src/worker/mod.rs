//! `amc worker`: runs the jobs that `amc serve --queue --store` replicas
//! accept. Any number of workers on any number of machines share one job
//! table and bucket; each runs one job at a time (size a machine with one
//! worker of `--threads` = its cores, or several single-threaded ones).
//!
//! A worker claims the oldest waiting job, downloads its upload, runs the
//! same pipeline as `amc stabilize` (`serve::work::stabilize`), renews its
//! lease and writes its progress twice a second, uploads the output and
//! telemetry and marks the job done or failed with the reason ([`job`]).
//! A job cancelled by `DELETE` is stopped within a second. On SIGTERM or
//! Ctrl-C it stops claiming, stops its running job and hands it back to
//! the queue (not counted as an attempt), then exits 0. It serves
//! `/healthz` and `/metrics` on `--addr` ([`http`]), and sweeps expired
//! jobs like the replicas do.

mod http;
mod job;

use crate::cluster::{redact, Cluster, ClusterConfig, ClusterError};
use crate::serve::metrics::Metrics;
use crate::serve::Limits;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// How often an idle worker looks for a job.
const IDLE_POLL: Duration = Duration::from_millis(500);
/// How often a worker sweeps expired jobs (every replica does too).
const SWEEP_EVERY: Duration = Duration::from_secs(10);

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
}

/// Why a worker could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    /// A setting outside its range.
    #[error("invalid --{flag}: {detail}")]
    Invalid {
        /// The setting's flag, without dashes.
        flag: &'static str,
        /// The value and what is allowed.
        detail: String,
    },
    /// The job table or the bucket.
    #[error(transparent)]
    Cluster(#[from] ClusterError),
    /// ffmpeg is missing.
    #[error(transparent)]
    Video(#[from] amc_video::VideoError),
    /// A folder the worker needs cannot be used.
    #[error("{}: {source}", path.display())]
    Io {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The listening socket or the runtime failed.
    #[error("{what}: {source}")]
    Network {
        /// What was being done.
        what: String,
        /// Why it failed.
        source: std::io::Error,
    },
}

impl WorkerConfig {
    fn limits(&self) -> Result<Limits, WorkerError> {
        let check = |flag: &'static str, v: u64, lo: u64, hi: u64| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(WorkerError::Invalid {
                    flag,
                    detail: format!("{v} (allowed: {lo}..={hi})"),
                })
            }
        };
        check("threads", self.threads as u64, 1, 256)?;
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
fn default_name() -> String {
    use rand::Rng;
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "worker".into());
    let suffix: u32 = rand::rngs::OsRng.gen();
    format!("{host}-{}-{:08x}", std::process::id(), suffix)
}

/// What the worker's tasks share.
pub(crate) struct WorkerState {
    pub cluster: Cluster,
    pub limits: Limits,
    pub name: String,
    pub work_dir: PathBuf,
    pub metrics: Arc<Metrics>,
    /// A job being run (for `/healthz`'s `busy`).
    pub busy: std::sync::atomic::AtomicBool,
}

/// Runs the worker until SIGTERM or Ctrl-C.
pub fn run(config: &WorkerConfig) -> Result<(), WorkerError> {
    let limits = config.limits()?;
    amc_video::ffmpeg_available()?;
    crate::serve::panics::install_hook();
    crate::serve::init_logs(config.log_json);
    let work_dir = config.work_dir.clone().unwrap_or_else(std::env::temp_dir);
    std::fs::create_dir_all(&work_dir).map_err(|source| WorkerError::Io {
        path: work_dir.clone(),
        source,
    })?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|source| WorkerError::Network {
            what: "cannot start the async runtime".into(),
            source,
        })?;
    runtime.block_on(async {
        let cluster =
            Cluster::connect(config.cluster.clone(), crate::serve::CONNECT_PATIENCE).await?;
        let name = config.name.clone().unwrap_or_else(default_name);
        let state = Arc::new(WorkerState {
            cluster,
            limits,
            name,
            work_dir,
            metrics: Arc::new(Metrics::new()),
            busy: false.into(),
        });
        let listener = tokio::net::TcpListener::bind(config.addr)
            .await
            .map_err(|source| WorkerError::Network {
                what: format!("cannot listen on {}", config.addr),
                source,
            })?;
        let addr = listener
            .local_addr()
            .map_err(|source| WorkerError::Network {
                what: format!("cannot listen on {}", config.addr),
                source,
            })?;
        // Tests and scripts read this line to find the port.
        println!("listening on http://{addr}");
        tracing::info!(%addr, worker = %state.name, queue = %redact(&state.cluster.config.queue_url), store = %state.cluster.store.location, threads = state.limits.threads, "amc worker started");
        let (stop_tx, stop) = watch::channel(false);
        tokio::spawn(async move {
            crate::serve::shutdown_signal().await;
            tracing::info!("stopping: no new jobs; a running one is handed back");
            stop_tx.send_replace(true);
        });
        let server = {
            let mut stop = stop.clone();
            let app = http::app(state.clone());
            tokio::spawn(async move {
                axum::serve(listener, app)
                    .with_graceful_shutdown(async move {
                        let _ = stop.wait_for(|s| *s).await;
                    })
                    .await
            })
        };
        work(&state, stop).await;
        let _ = server.await;
        tracing::info!(worker = %state.name, "stopped");
        Ok(())
    })
}

/// Claims and runs jobs until `stop`.
async fn work(state: &Arc<WorkerState>, mut stop: watch::Receiver<bool>) {
    let mut last_sweep: Option<tokio::time::Instant> = None;
    while !*stop.borrow() {
        if last_sweep.is_none_or(|t| t.elapsed() >= SWEEP_EVERY) {
            last_sweep = Some(tokio::time::Instant::now());
            match state.cluster.sweep().await {
                Ok((failed, expired)) if failed + expired as u64 > 0 => {
                    tracing::info!(failed, expired, "swept the job table")
                }
                Ok(_) => {}
                Err(e) => tracing::warn!(error = %e, "cannot sweep the job table now"),
            }
        }
        let config = &state.cluster.config;
        let pause = match state
            .cluster
            .queue
            .claim(&state.name, config.lease, config.max_attempts)
            .await
        {
            Ok(Some(claim)) => {
                if !job::run(state, claim, &mut stop).await {
                    continue;
                }
                // Handed back because the bucket or the disk failed it.
                Duration::from_secs(2)
            }
            Ok(None) => IDLE_POLL,
            Err(e) => {
                tracing::warn!(error = %e, "cannot claim a job now; retrying");
                Duration::from_secs(2)
            }
        };
        tokio::select! {
            _ = tokio::time::sleep(pause) => {}
            _ = stop.wait_for(|s| *s) => {}
        }
    }
}
