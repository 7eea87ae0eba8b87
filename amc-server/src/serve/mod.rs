//! `amc serve`: the HTTP service.
//!
//! | route | what |
//! |---|---|
//! | `POST /stabilize` | clip in (raw body or multipart), stabilized clip out, metrics in `X-Amc-*` headers |
//! | `POST /jobs`, `GET/DELETE /jobs/{id}`, `GET /jobs/{id}/output`, `GET /jobs/{id}/telemetry.csv` | batch jobs |
//! | `GET /live` (WebSocket) | the stabilized live feed: a JPEG then a JSON telemetry message per frame |
//! | `GET /live/ingest` (WebSocket) | a publisher's JPEG frames, when there is no `--live-source` |
//! | `GET /healthz`, `GET /metrics`, `GET /openapi.json` | operations |
//! | `GET /` | the web page (`--web-dir`) |
//!
//! CPU work runs on blocking threads, at most `--workers` at once (a
//! semaphore); at most `--workers + --queue` clips are accepted at once and
//! the rest get 503 with `Retry-After`. Uploads and results live in
//! per-request scratch folders under the work directory, removed with their
//! request or job, and the work directory itself is removed on shutdown.

mod intake;
mod jobs;
mod live;
mod metrics;
mod openapi;
mod options;
mod problem;
mod stabilize;
mod storage;
#[cfg(test)]
mod tests;
mod upload;
mod work;

pub use live::LiveConfig;

use amc_core::view::Mode;
use axum::extract::{DefaultBodyLimit, State};
use axum::handler::HandlerWithoutStateExt;
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use metrics::Metrics;
use problem::ApiError;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use storage::DiskBudget;
use tokio::sync::{watch, Semaphore};
use tokio_util::task::TaskTracker;
use tower_http::services::ServeDir;
use tower_http::trace::TraceLayer;

/// `amc serve` settings (the command line's flags, one field each).
#[derive(Debug, Clone)]
pub struct ServeConfig {
    /// Address to listen on (port 0 picks a free port; the chosen one is printed).
    pub addr: SocketAddr,
    /// Folder of the web page served at `/` (built by `bash web/build.sh`).
    pub web_dir: PathBuf,
    /// Folder for uploads and results (default: a new folder in the system's temp dir,
    /// removed on exit).
    pub work_dir: Option<PathBuf>,
    /// Largest upload, megabytes.
    pub max_upload_mb: u64,
    /// Widest video accepted, pixels.
    pub max_width: usize,
    /// Tallest video accepted, pixels.
    pub max_height: usize,
    /// Longest video accepted, seconds.
    pub max_duration: f64,
    /// Clips processed at once (default: the number of CPU cores).
    pub workers: Option<usize>,
    /// Clips accepted beyond those being processed (they wait); more get 503.
    pub queue: usize,
    /// Longest a clip may take to process, seconds.
    pub job_time_limit: u64,
    /// How long a finished job's results are kept, seconds.
    pub job_ttl: u64,
    /// Disk space uploads and results may use together, megabytes.
    pub max_disk_mb: u64,
    /// Longest an ffmpeg child may stall before it is killed, seconds.
    pub ffmpeg_timeout: u64,
    /// Live feed source: a file, an RTSP/UDP/SRT URL or a device (anything ffmpeg opens).
    /// Without it, the feed comes from a publisher on /live/ingest.
    pub live_source: Option<String>,
    /// Replay a file --live-source forever.
    pub live_loop: bool,
    /// ffmpeg input format of --live-source (e.g. v4l2 for /dev/video0).
    pub live_format: Option<String>,
    /// Live feed mode: stabilize or saccade.
    pub live_mode: Mode,
    /// Horizontal field of view of the live camera, degrees (a pinhole).
    pub live_fov: f64,
    /// Lens file of the live camera (as for `amc stabilize --lens`).
    pub live_lens: Option<PathBuf>,
    /// Frames averaged into each live output frame (1..=64).
    pub live_n_avg: usize,
    /// Share cropped from each side of the live output (0..=0.45).
    pub live_margin: f64,
    /// Width of the live output in pixels (default: the cropped input width).
    pub live_width: Option<usize>,
    /// JPEG quality of live frames (1..=100).
    pub live_jpeg_quality: u8,
    /// Log one JSON object per line (for log collectors) instead of text.
    /// The level is set with RUST_LOG (default: info).
    pub log_json: bool,
}

/// The service's limits, from the flags.
#[derive(Clone, Debug)]
pub struct Limits {
    pub max_upload_bytes: u64,
    pub max_width: usize,
    pub max_height: usize,
    pub max_duration_s: f64,
    pub workers: usize,
    pub queue: usize,
    pub job_time_limit: Duration,
    pub job_ttl: Duration,
    pub max_disk_bytes: u64,
    pub ffmpeg_timeout: Duration,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_upload_bytes: 2_000_000_000,
            max_width: 3840,
            max_height: 2160,
            max_duration_s: 1800.0,
            workers: default_workers(),
            queue: 8,
            job_time_limit: Duration::from_secs(3600),
            job_ttl: Duration::from_secs(3600),
            max_disk_bytes: 20_000_000_000,
            ffmpeg_timeout: Duration::from_secs(60),
        }
    }
}

fn default_workers() -> usize {
    std::thread::available_parallelism().map_or(2, |n| n.get())
}

/// Why the service could not start or stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A setting outside its range.
    #[error("invalid --{flag}: {detail}")]
    Invalid {
        /// The setting's flag, without dashes.
        flag: &'static str,
        /// The value and what is allowed.
        detail: String,
    },
    /// The live camera's parameters or lens are refused by the core.
    #[error(transparent)]
    Core(#[from] amc_core::AmcError),
    /// ffmpeg is missing.
    #[error(transparent)]
    Video(#[from] amc_video::VideoError),
    /// A file or folder the service needs cannot be used.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
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

fn check<T: PartialOrd + std::fmt::Display>(
    flag: &'static str,
    value: T,
    lo: T,
    hi: T,
) -> Result<(), ServeError> {
    if value < lo || value > hi {
        return Err(ServeError::Invalid {
            flag,
            detail: format!("{value} (allowed: {lo}..={hi})"),
        });
    }
    Ok(())
}

impl ServeConfig {
    /// Checks the flags and turns them into limits.
    pub fn limits(&self) -> Result<Limits, ServeError> {
        let workers = self.workers.unwrap_or_else(default_workers);
        check("max-upload-mb", self.max_upload_mb, 1, 1_000_000)?;
        check("max-width", self.max_width, 16, 16384)?;
        check("max-height", self.max_height, 16, 16384)?;
        check("max-duration", self.max_duration, 0.1, 86_400.0)?;
        check("workers", workers, 1, 256)?;
        check("queue", self.queue, 0, 10_000)?;
        check("job-time-limit", self.job_time_limit, 1, 604_800)?;
        check("job-ttl", self.job_ttl, 1, 2_592_000)?;
        check("max-disk-mb", self.max_disk_mb, 1, 1_000_000_000)?;
        check("ffmpeg-timeout", self.ffmpeg_timeout, 1, 86_400)?;
        if self.max_disk_mb < self.max_upload_mb {
            return Err(ServeError::Invalid {
                flag: "max-disk-mb",
                detail: format!(
                    "{} (allowed: at least --max-upload-mb, {})",
                    self.max_disk_mb, self.max_upload_mb
                ),
            });
        }
        Ok(Limits {
            max_upload_bytes: self.max_upload_mb * 1_000_000,
            max_width: self.max_width,
            max_height: self.max_height,
            max_duration_s: self.max_duration,
            workers,
            queue: self.queue,
            job_time_limit: Duration::from_secs(self.job_time_limit),
            job_ttl: Duration::from_secs(self.job_ttl),
            max_disk_bytes: self.max_disk_mb * 1_000_000,
            ffmpeg_timeout: Duration::from_secs(self.ffmpeg_timeout),
        })
    }

    /// The live feed's configuration.
    pub fn live(&self) -> Result<LiveConfig, ServeError> {
        check("live-jpeg-quality", self.live_jpeg_quality, 1, 100)?;
        // The same range as every other field of view (`fov`).
        if amc_core::LensSpec::parse_fov(&self.live_fov.to_string()).is_err() {
            return Err(ServeError::Invalid {
                flag: "live-fov",
                detail: format!("{} (allowed: 0 < DEG <= 179)", self.live_fov),
            });
        }
        let mut params = amc_core::StabilizerParams::default();
        params.view.mode = self.live_mode;
        params.render.n_avg = self.live_n_avg;
        params.render.margin = self.live_margin;
        params.render.output_width = self.live_width;
        params.validate()?;
        let lens = match &self.live_lens {
            Some(p) => {
                let text = std::fs::read_to_string(p).map_err(|source| ServeError::Io {
                    path: p.clone(),
                    source,
                })?;
                Some(amc_core::lens::parse_lens(&text).map_err(amc_core::AmcError::from)?)
            }
            None => None,
        };
        Ok(LiveConfig {
            source: self.live_source.clone(),
            format: self.live_format.clone(),
            looped: self.live_loop,
            params,
            lens,
            fov_deg: self.live_fov,
            jpeg_quality: self.live_jpeg_quality,
            ffmpeg_timeout: Duration::from_secs(self.ffmpeg_timeout),
        })
    }
}

/// Everything the handlers share.
pub struct AppState {
    pub limits: Limits,
    pub work_dir: PathBuf,
    pub web_dir: PathBuf,
    /// One permit per clip processed at once.
    pub cpu: Arc<Semaphore>,
    /// One permit per clip accepted (processing or waiting).
    pub admission: Arc<Semaphore>,
    pub disk: Arc<DiskBudget>,
    pub jobs: jobs::JobStore,
    pub live: Arc<live::LiveHub>,
    pub metrics: Arc<Metrics>,
    /// Every spawned task and blocking worker, awaited on shutdown.
    pub tasks: TaskTracker,
    /// Becomes true when the service is shutting down.
    pub shutdown: watch::Sender<bool>,
}

impl AppState {
    /// State with its work directory at `work_dir` (created if missing).
    pub fn new(
        limits: Limits,
        work_dir: PathBuf,
        web_dir: PathBuf,
        live: LiveConfig,
    ) -> std::io::Result<Arc<Self>> {
        std::fs::create_dir_all(&work_dir)?;
        let metrics = Arc::new(Metrics::new());
        metrics.disk_limit.set(limits.max_disk_bytes as i64);
        Ok(Arc::new(Self {
            cpu: Arc::new(Semaphore::new(limits.workers)),
            admission: Arc::new(Semaphore::new(limits.workers + limits.queue)),
            disk: Arc::new(DiskBudget::new(limits.max_disk_bytes)),
            jobs: jobs::JobStore::default(),
            live: live::LiveHub::start(live, metrics.clone()),
            metrics,
            tasks: TaskTracker::new(),
            shutdown: watch::channel(false).0,
            limits,
            work_dir,
            web_dir,
        }))
    }

    /// Answers a refused request, counting it for `/metrics`.
    pub fn refuse(&self, e: ApiError) -> Response {
        self.metrics.reject(e.status().as_u16());
        e.into_response()
    }
}

/// The router, separate from `main` so tests can drive it without a socket.
pub fn app(state: Arc<AppState>) -> Router {
    let api = Router::new()
        .route("/stabilize", post(stabilize::handler))
        .route("/jobs", post(jobs::create))
        .route("/jobs/{id}", get(jobs::get).delete(jobs::delete))
        .route("/jobs/{id}/output", get(jobs::output))
        .route("/jobs/{id}/telemetry.csv", get(jobs::telemetry))
        // Uploads are streamed to disk under our own limit.
        .layer(DefaultBodyLimit::disable())
        .route("/live", get(live::viewer))
        .route("/live/ingest", get(live::ingest))
        .route("/healthz", get(healthz))
        .route("/metrics", get(prometheus))
        .route("/openapi.json", get(openapi::document));
    let index = state.web_dir.join("index.html");
    let router = if index.is_file() {
        // The page's files; anything else is an unknown endpoint (problem+json 404).
        api.fallback_service(
            ServeDir::new(&state.web_dir).not_found_service(no_page.into_service()),
        )
    } else {
        api.fallback(no_page)
    };
    router
        .method_not_allowed_fallback(method_not_allowed)
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

/// `GET /healthz`: 200 while the service can work (ffmpeg runs, the work dir is writable).
async fn healthz(State(state): State<Arc<AppState>>) -> Response {
    let work_dir = state.work_dir.clone();
    let check = tokio::task::spawn_blocking(move || -> Result<(), String> {
        amc_video::ffmpeg_available().map_err(|e| e.to_string())?;
        tempfile::tempfile_in(&work_dir).map_err(|e| format!("work dir not writable: {e}"))?;
        Ok(())
    })
    .await
    .unwrap_or_else(|e| Err(e.to_string()));
    let body = |status: &str, detail: Option<String>| {
        Json(serde_json::json!({
            "status": status,
            "detail": detail,
            "version": env!("CARGO_PKG_VERSION"),
            "workers": state.limits.workers,
            "busy": state.limits.workers - state.cpu.available_permits().min(state.limits.workers),
        }))
    };
    match check {
        Ok(()) => body("ok", None).into_response(),
        Err(e) => (
            StatusCode::SERVICE_UNAVAILABLE,
            body("unavailable", Some(e)),
        )
            .into_response(),
    }
}

/// `GET /metrics`.
async fn prometheus(State(state): State<Arc<AppState>>) -> Response {
    let counts = state.jobs.counts();
    for s in jobs::JobState::ALL {
        state
            .metrics
            .jobs
            .get_or_create(&metrics::StateLabel { state: s.name() })
            .set(counts.get(&s).copied().unwrap_or(0) as i64);
    }
    state.metrics.disk_used.set(state.disk.used() as i64);
    let mut res = state.metrics.encode().into_response();
    res.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("text/plain; version=0.0.4; charset=utf-8"),
    );
    res
}

/// `/` when the page is not built, and unknown paths.
async fn no_page(uri: axum::http::Uri) -> Response {
    if uri.path() == "/" || uri.path() == "/index.html" {
        return Html(
            "<!doctype html><title>amc</title><h1>amc serve</h1>\
             <p>The web page is not built: run <code>bash web/build.sh</code> and start \
             <code>amc serve</code> from the repository root (or pass <code>--web-dir</code>).</p>\
             <p>The API is described at <a href=\"/openapi.json\">/openapi.json</a>.</p>",
        )
        .into_response();
    }
    ApiError::NoRoute(format!(
        "no such endpoint: {} (the API is described at /openapi.json)",
        uri.path()
    ))
    .into_response()
}

async fn method_not_allowed(method: axum::http::Method, uri: axum::http::Uri) -> Response {
    ApiError::MethodNotAllowed(format!(
        "{method} is not allowed on {} (the API is described at /openapi.json)",
        uri.path()
    ))
    .into_response()
}

/// Waits for Ctrl-C or SIGTERM.
async fn shutdown_signal() {
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

/// Runs the service until Ctrl-C or SIGTERM.
pub fn run(args: &ServeConfig) -> Result<(), ServeError> {
    let limits = args.limits()?;
    let live = args.live()?;
    amc_video::ffmpeg_available()?;
    let (work_dir, owned_dir) = match &args.work_dir {
        Some(d) => {
            let io = |source| ServeError::Io {
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
                .map_err(|source| ServeError::Io {
                    path: std::env::temp_dir(),
                    source,
                })?;
            (dir.path().to_path_buf(), dir)
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let logs = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    let _ = if args.log_json {
        logs.json().try_init()
    } else {
        logs.with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
            .try_init()
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|source| ServeError::Network {
            what: "cannot start the async runtime".into(),
            source,
        })?;
    let state =
        AppState::new(limits, work_dir.clone(), args.web_dir.clone(), live).map_err(|source| {
            ServeError::Io {
                path: work_dir.clone(),
                source,
            }
        })?;
    runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind(args.addr)
            .await
            .map_err(|source| ServeError::Network {
                what: format!("cannot listen on {}", args.addr),
                source,
            })?;
        let addr = listener
            .local_addr()
            .map_err(|source| ServeError::Network {
                what: format!("cannot listen on {}", args.addr),
                source,
            })?;
        // Tests and scripts read this line to find the port.
        println!("listening on http://{addr}");
        tracing::info!(%addr, work_dir = %work_dir.display(), web_dir = %args.web_dir.display(), workers = state.limits.workers, "amc serve started");
        let ticker = {
            let state = state.clone();
            tokio::spawn(async move {
                let mut tick = tokio::time::interval(Duration::from_secs(1));
                let sweep_every = (state.limits.job_ttl / 4).clamp(Duration::from_secs(1), Duration::from_secs(30));
                let mut last_sweep = tokio::time::Instant::now();
                loop {
                    tick.tick().await;
                    state.metrics.sample();
                    if last_sweep.elapsed() >= sweep_every {
                        last_sweep = tokio::time::Instant::now();
                        let n = state.jobs.expire(state.limits.job_ttl);
                        if n > 0 {
                            tracing::info!(expired = n, "finished jobs removed");
                        }
                    }
                }
            })
        };
        let shutdown_state = state.clone();
        let served = axum::serve(listener, app(state.clone()))
            .with_graceful_shutdown(async move {
                shutdown_signal().await;
                tracing::info!("shutting down: cancelling jobs, closing live connections");
                shutdown_state.shutdown.send_replace(true);
                shutdown_state.jobs.cancel_all();
                shutdown_state.live.stop();
            })
            .await;
        ticker.abort();
        state.tasks.close();
        let _ = tokio::time::timeout(Duration::from_secs(30), state.tasks.wait()).await;
        state.jobs.clear();
        served.map_err(|source| ServeError::Network {
            what: "the server failed".into(),
            source,
        })
    })?;
    drop(state);
    drop(owned_dir);
    tracing::info!("stopped; work directory removed");
    Ok(())
}
