//! [`run`]: boots the worker (logs, runtime, the job table, its HTTP
//! endpoints) and claims and runs jobs until SIGTERM or Ctrl-C.

use super::config::{default_name, WorkerConfig, WorkerError};
use super::state::WorkerState;
use super::{http, job, scratch};
use crate::cluster::{redact, Cluster};
use crate::serve::metrics::Metrics;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;

/// How often an idle worker looks for a job.
const IDLE_POLL: Duration = Duration::from_millis(500);
/// How often a worker sweeps expired jobs (every replica does too).
const SWEEP_EVERY: Duration = Duration::from_secs(10);

/// Runs the worker until SIGTERM or Ctrl-C.
pub fn run(config: &WorkerConfig) -> Result<(), WorkerError> {
    let limits = config.limits()?;
    config.check_access()?;
    let auth = Arc::new(crate::auth::Auth::new(
        config.auth.clone(),
        crate::auth::Tickets::local(),
    )?);
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
        let host = scratch::host();
        let name = config.name.clone().unwrap_or_else(|| default_name(&host));
        // Folders left by workers of this host that were killed (SIGKILL).
        for stale in scratch::remove_stale(&work_dir, &host) {
            tracing::info!(folder = %stale.display(), "removed the job folder of a worker that is gone");
        }
        let state = Arc::new(WorkerState {
            cluster,
            limits,
            name,
            host,
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
            let app = http::app(state.clone(), auth.clone());
            let ticker = auth.clone();
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(Duration::from_secs(1));
                loop {
                    tick.tick().await;
                    ticker.tick();
                }
            });
            tokio::spawn(async move {
                axum::serve(
                    listener,
                    app.into_make_service_with_connect_info::<std::net::SocketAddr>(),
                )
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
