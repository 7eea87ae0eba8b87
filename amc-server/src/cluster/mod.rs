//! The shared job infrastructure that lets the service run on many
//! machines: jobs are rows in PostgreSQL ([`queue`]), uploads and results
//! are objects in an S3-compatible bucket ([`store`]). `amc serve --queue
//! URL --store s3://BUCKET` replicas accept and answer for jobs; `amc
//! worker`s (the `worker` module) claim and run them. Without those flags
//! none of this is used: the service keeps its jobs in memory and on local
//! disk, as it always did.
//!
//! Layers: `config` and `error` at the bottom, then `queue` and `store`,
//! then [`Cluster`] here (both together: connecting, health, expiry).

mod config;
mod error;
pub mod queue;
pub mod store;
mod tickets;

pub use config::{redact, ClusterConfig, StoreConfig};
pub use error::ClusterError;
pub use queue::Queue;
pub use store::Store;

use std::time::Duration;

/// Expired jobs removed per sweep (the next sweep takes the rest).
const SWEEP_BATCH: i64 = 100;

/// The job table and the bucket, together.
#[derive(Clone)]
pub struct Cluster {
    pub queue: Queue,
    pub store: Store,
    pub config: ClusterConfig,
}

impl Cluster {
    /// Connects to both (waiting up to `patience` for a database that is
    /// still starting) and brings the job table's schema up to date.
    pub async fn connect(config: ClusterConfig, patience: Duration) -> Result<Self, ClusterError> {
        config.validate()?;
        let store = Store::new(&config.store)?;
        let queue = Queue::connect(&config.queue_url, patience).await?;
        Ok(Self {
            queue,
            store,
            config,
        })
    }

    /// Checks the database and the bucket; the error says which is down.
    pub async fn ping(&self) -> Result<(), ClusterError> {
        self.queue.ping().await?;
        self.store.ping().await
    }

    /// One round of housekeeping, safe on every replica and worker at once:
    /// fails jobs whose workers kept dying, and removes finished jobs older
    /// than the TTL with their objects. Returns (failed, expired).
    pub async fn sweep(&self) -> Result<(u64, usize), ClusterError> {
        let failed = self.queue.fail_abandoned(self.config.max_attempts).await?;
        let store = &self.store;
        let expired = self
            .queue
            .expire(self.config.job_ttl, SWEEP_BATCH, |id, tenant| async move {
                store.delete_job(&tenant, &id).await.map(|_| ())
            })
            .await?;
        self.queue.expire_tickets().await?;
        Ok((failed, expired))
    }
}
