//! [`run`]: boots the service (logging, the async runtime, the listener, the
//! once-a-second ticker) and shuts it down gracefully on Ctrl-C or SIGTERM.

use super::config::{ServeConfig, ServeError, ServiceError};
use super::router::app;
use super::state::AppState;
use crate::auth::{Auth, Tickets};
use crate::cluster::{redact, Cluster};
use std::io::IsTerminal;
use std::sync::Arc;
use std::time::Duration;

/// Waits for Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}

/// How long start-up waits for the job table's database (containers start
/// in any order).
pub const CONNECT_PATIENCE: Duration = Duration::from_secs(60);

/// Removes expired jobs: from this process's table, or (every replica and
/// worker sweeps; rows are locked one sweeper at a time) from the shared
/// table and bucket, failing jobs whose workers kept dying too.
async fn sweep(state: &Arc<AppState>) {
    match &state.cluster {
        None => {
            let n = state.jobs.expire(state.limits.job_ttl);
            if n > 0 {
                tracing::info!(expired = n, "finished jobs removed");
            }
        }
        Some(cluster) => match cluster.sweep().await {
            Ok((failed, expired)) => {
                if failed > 0 {
                    tracing::warn!(failed, "jobs failed: their workers kept dying");
                }
                if expired > 0 {
                    tracing::info!(expired, "finished jobs and their objects removed");
                }
            }
            Err(e) => tracing::warn!(error = %e, "cannot sweep the job table now"),
        },
    }
}

/// Logs to stderr at RUST_LOG's level (default: info), one JSON object per
/// line with `json`.
pub fn init_logs(json: bool) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info,sqlx=warn"));
    // Colours only for a person at a terminal; never in JSON (log collectors)
    // nor in a file or pipe. This covers every event, the HTTP trace
    // layer's spans and fields included.
    let colour = !json && std::io::stderr().is_terminal();
    let logs = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(colour);
    let _ = if json {
        logs.json().try_init()
    } else {
        logs.try_init()
    };
}

/// Runs the service until Ctrl-C or SIGTERM.
pub fn run(args: &ServeConfig) -> Result<(), ServeError> {
    args.check_access()?;
    let tls = args.listen.tls()?;
    let limits = args.limits()?;
    let live = args.live()?;
    amc_video::ffmpeg_available()?;
    super::panics::install_hook();
    let (work_dir, owned_dir) = match &args.work_dir {
        Some(d) => {
            let io = |source| ServiceError::Io {
                path: d.clone(),
                source,
            };
            std::fs::create_dir_all(d).map_err(io)?;
            let dir = tempfile::Builder::new()
                .prefix("amc-serve-")
                .tempdir_in(d)
                .map_err(io)?;
            (dir.path().to_path_buf(), dir)
        }
        None => {
            let dir = tempfile::Builder::new()
                .prefix("amc-serve-")
                .tempdir()
                .map_err(|source| ServiceError::Io {
                    path: std::env::temp_dir(),
                    source,
                })?;
            (dir.path().to_path_buf(), dir)
        }
    };
    init_logs(args.log_json);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|source| ServiceError::Network {
            what: "cannot start the async runtime".into(),
            source,
        })?;
    runtime.block_on(async {
        let cluster = match &args.cluster {
            Some(config) => {
                let cluster = Cluster::connect(config.clone(), CONNECT_PATIENCE).await?;
                tracing::info!(queue = %redact(&config.queue_url), store = %cluster.store.location, "jobs are kept in the shared job table and bucket");
                Some(cluster)
            }
            None => None,
        };
        let tickets = match &cluster {
            Some(c) => Tickets::Shared(c.queue.clone()),
            None => Tickets::local(),
        };
        let auth = Arc::new(Auth::new(args.auth.clone(), tickets).map_err(ServiceError::from)?);
        let state = AppState::new(limits, work_dir.clone(), args.web_dir.clone(), live, cluster, auth)
            .map_err(|source| ServiceError::Io {
                path: work_dir.clone(),
                source,
            })?;
        let listener = tokio::net::TcpListener::bind(args.addr)
            .await
            .map_err(|source| ServiceError::Network {
                what: format!("cannot listen on {}", args.addr),
                source,
            })?;
        let addr = listener
            .local_addr()
            .map_err(|source| ServiceError::Network {
                what: format!("cannot listen on {}", args.addr),
                source,
            })?;
        // Tests and scripts read this line to find the port.
        let scheme = if tls.is_some() { "https" } else { "http" };
        println!("listening on {scheme}://{addr}");
        if state.auth.enabled() {
            tracing::info!(keys = state.auth.key_count(), file = %args.auth.keys_file.as_deref().unwrap_or(std::path::Path::new("")).display(), "requests need an API key");
        } else if !addr.ip().is_loopback() {
            tracing::warn!(%addr, "serving without keys (--insecure-no-auth): whoever reaches this address may use every endpoint");
        }
        tracing::info!(%addr, tls = tls.is_some(), work_dir = %work_dir.display(), web_dir = %args.web_dir.display(), workers = state.limits.workers, "amc serve started");
        if !args.web_dir.join("index.html").is_file() {
            let dir = std::path::absolute(&args.web_dir).unwrap_or_else(|_| args.web_dir.clone());
            tracing::warn!(
                "the web page is not built: {} has no index.html. Build it with `bash web/build.sh` \
                 in the repository (it writes web/dist), or pass --web-dir with a built page; \
                 until then / shows a note, and the page is served as soon as it is built",
                dir.display()
            );
        }
        let ticker = {
            let state = state.clone();
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(Duration::from_secs(1));
                let sweep_every = (state.limits.job_ttl / 4).clamp(Duration::from_secs(1), Duration::from_secs(30));
                let mut last_sweep = tokio::time::Instant::now();
                loop {
                    tick.tick().await;
                    state.metrics.sample();
                    state.auth.tick();
                    if last_sweep.elapsed() >= sweep_every {
                        last_sweep = tokio::time::Instant::now();
                        sweep(&state).await;
                    }
                }
            })
        };
        let shutdown_state = state.clone();
        let shutdown = async move {
            shutdown_signal().await;
            tracing::info!("shutting down: cancelling jobs, closing live connections");
            shutdown_state.shutdown.send_replace(true);
            shutdown_state.jobs.cancel_all();
            shutdown_state.live.stop();
        };
        super::listen::serve(listener, app(state.clone()), &args.listen, tls, shutdown, Duration::from_secs(30)).await;
        ticker.abort();
        state.tasks.close();
        let _ = tokio::time::timeout(Duration::from_secs(30), state.tasks.wait()).await;
        state.jobs.clear();
        Ok::<(), ServeError>(())
    })?;
    // Threads still blocked on a child (a live source on a quiet network
    // stream) end with the process; their children must not outlive it.
    let killed = amc_video::cleanup::kill_children();
    if killed > 0 {
        tracing::info!(
            children = killed,
            "stopped the ffmpeg children still running"
        );
    }
    drop(owned_dir);
    tracing::info!("stopped; work directory removed");
    Ok(())
}
