//! [`AppState`]: what every handler shares (limits, semaphores, the disk
//! budget, the job table, the live hub, metrics, the task tracker and the
//! shutdown flag).

use super::config::Limits;
use super::jobs::JobStore;
use super::live::{LiveConfig, LiveHub};
use super::metrics::Metrics;
use super::problem::ApiError;
use super::storage::DiskBudget;
use crate::auth::Auth;
use crate::cluster::Cluster;
use axum::response::{IntoResponse, Response};
use std::path::PathBuf;
use std::sync::Arc;
use tokio::sync::{watch, Semaphore};
use tokio_util::task::TaskTracker;

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
    /// Jobs kept in this process (without `--queue`).
    pub jobs: JobStore,
    /// The shared job table and bucket (`--queue`/`--store`): jobs live
    /// there instead, and `amc worker`s run them.
    pub cluster: Option<Cluster>,
    pub live: Arc<LiveHub>,
    /// Keys, tickets and limits (docs/security.md).
    pub auth: Arc<Auth>,
    pub metrics: Arc<Metrics>,
    /// Every spawned task and blocking worker, awaited on shutdown.
    pub tasks: TaskTracker,
    /// Becomes true when the service is shutting down.
    pub shutdown: watch::Sender<bool>,
    /// Test-only trigger: workers panic while set (the panic path's tests).
    #[cfg(test)]
    pub panic_in_workers: std::sync::atomic::AtomicBool,
}

impl AppState {
    /// Whether the test-only trigger asks workers to panic (never, outside
    /// this crate's unit tests).
    pub fn panics_for_test(&self) -> bool {
        #[cfg(test)]
        return self
            .panic_in_workers
            .load(std::sync::atomic::Ordering::SeqCst);
        #[cfg(not(test))]
        false
    }

    /// State with its work directory at `work_dir` (created if missing),
    /// its jobs in `cluster` when given, else in this process.
    pub fn new(
        limits: Limits,
        work_dir: PathBuf,
        web_dir: PathBuf,
        live: LiveConfig,
        cluster: Option<Cluster>,
        auth: Arc<Auth>,
    ) -> std::io::Result<Arc<Self>> {
        std::fs::create_dir_all(&work_dir)?;
        let metrics = Arc::new(Metrics::new());
        metrics.disk_limit.set(limits.max_disk_bytes as i64);
        Ok(Arc::new(Self {
            cpu: Arc::new(Semaphore::new(limits.workers)),
            admission: Arc::new(Semaphore::new(limits.workers + limits.queue)),
            disk: Arc::new(DiskBudget::new(limits.max_disk_bytes)),
            jobs: JobStore::default(),
            cluster,
            live: LiveHub::start(live, metrics.clone()),
            auth,
            metrics,
            tasks: TaskTracker::new(),
            shutdown: watch::channel(false).0,
            #[cfg(test)]
            panic_in_workers: std::sync::atomic::AtomicBool::new(false),
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

/// Resolves once the service starts shutting down.
pub async fn until_shutdown(rx: &mut watch::Receiver<bool>) {
    let _ = rx.wait_for(|s| *s).await;
}
