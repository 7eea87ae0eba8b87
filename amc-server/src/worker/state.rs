//! [`WorkerState`]: what the worker's tasks (the claim loop, the job's
//! heartbeat, the HTTP endpoints) share.

use crate::cluster::Cluster;
use crate::serve::metrics::Metrics;
use crate::serve::Limits;
use std::path::PathBuf;
use std::sync::Arc;

/// What the worker's tasks share.
pub(crate) struct WorkerState {
    pub cluster: Cluster,
    pub limits: Limits,
    pub name: String,
    /// This host's name (in job folder names).
    pub host: String,
    pub work_dir: PathBuf,
    pub metrics: Arc<Metrics>,
    /// A job being run (for `/healthz`'s `busy`).
    pub busy: std::sync::atomic::AtomicBool,
}
