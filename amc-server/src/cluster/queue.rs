//! [`Queue`]: the job table in PostgreSQL. Each job is one row
//! (`migrations/0001_jobs.sql`); every replica and worker reads and writes
//! the same rows, so any of them can answer for any job.
//!
//! A job's life, each step one statement (so two processes never both win):
//! - a replica inserts it `queued`;
//! - a worker [claims](Queue::claim) the oldest queued row, or a running one
//!   whose lease ran out, with `FOR UPDATE SKIP LOCKED` (workers never wait
//!   on each other's rows), counting the attempt;
//! - the worker [renews](Queue::heartbeat) its lease twice a second,
//!   writing its progress; a renewal that matches no row means the job was
//!   cancelled or given to another worker, and the worker stops;
//! - it [finishes](Queue::finish) the row, only if the row is still its own
//!   claim (id, attempt and worker all match);
//! - rows whose workers died more than `max_attempts` times are
//!   [failed](Queue::fail_abandoned); finished rows expire after the TTL.

use super::error::ClusterError;
use sqlx::migrate::{Migration, MigrationType, Migrator};
use sqlx::postgres::{PgPool, PgPoolOptions, PgRow};
use sqlx::Row;
use std::borrow::Cow;
use std::time::Duration;

/// The job table's schema, in order. sqlx records which ran in
/// `_sqlx_migrations` and holds an advisory lock while it migrates, so
/// replicas starting at once run each migration exactly once.
fn migrator() -> Migrator {
    let migration = |version, description: &'static str, sql: &'static str| {
        Migration::new(
            version,
            Cow::Borrowed(description),
            MigrationType::Simple,
            sqlx::SqlStr::from_static(sql),
            false,
        )
    };
    Migrator {
        migrations: Cow::Owned(vec![
            migration(1, "jobs", include_str!("../../migrations/0001_jobs.sql")),
            migration(
                2,
                "tenants",
                include_str!("../../migrations/0002_tenants.sql"),
            ),
            migration(3, "gyro", include_str!("../../migrations/0003_gyro.sql")),
        ]),
        ..Migrator::DEFAULT
    }
}

/// How long a request waits for a database connection before it is
/// answered 503: a database that is down must not hang clients.
const ACQUIRE_TIMEOUT: Duration = Duration::from_secs(3);

/// The columns every read returns, in [`JobRow`]'s shape.
const COLUMNS: &str = "id, tenant, seq, state, extract(epoch from created_at)::float8 AS created, \
    format, frames_total, frames_done, attempts, error, metrics::text AS metrics, \
    motion::text AS motion, input_key, output_key, telemetry_key, \
    (lease_until IS NULL OR lease_until < now()) AS released";

/// A job as the table holds it.
#[derive(Clone, Debug)]
pub struct JobRow {
    pub id: String,
    /// The tenant whose key submitted it (`local` without keys).
    pub tenant: String,
    /// Order of acceptance (the listing's cursor).
    pub seq: i64,
    /// `queued`, `running`, `done`, `failed` or `cancelled`.
    pub state: String,
    /// When it was accepted, seconds since the Unix epoch.
    pub created: f64,
    /// Output container (`mp4`, `webm`).
    pub format: String,
    pub frames_total: Option<i64>,
    pub frames_done: i64,
    /// Claims so far (1 on the first run; more after a worker died).
    pub attempts: i32,
    pub error: Option<String>,
    /// The finished job's measurements, JSON.
    pub metrics: Option<String>,
    /// The finished job's motion summary, JSON.
    pub motion: Option<String>,
    pub input_key: String,
    pub output_key: Option<String>,
    pub telemetry_key: Option<String>,
    /// No live worker holds the job (it never ran, its worker let go, or
    /// its worker's lease ran out).
    pub released: bool,
}

impl JobRow {
    fn of(row: &PgRow) -> Result<Self, sqlx::Error> {
        Ok(Self {
            id: row.try_get("id")?,
            tenant: row.try_get("tenant")?,
            seq: row.try_get("seq")?,
            state: row.try_get("state")?,
            created: row.try_get("created")?,
            format: row.try_get("format")?,
            frames_total: row.try_get("frames_total")?,
            frames_done: row.try_get("frames_done")?,
            attempts: row.try_get("attempts")?,
            error: row.try_get("error")?,
            metrics: row.try_get("metrics")?,
            motion: row.try_get("motion")?,
            input_key: row.try_get("input_key")?,
            output_key: row.try_get("output_key")?,
            telemetry_key: row.try_get("telemetry_key")?,
            released: row.try_get("released")?,
        })
    }
}

/// A job to insert.
pub struct NewJob<'a> {
    pub id: &'a str,
    pub tenant: &'a str,
    /// The request's query string (the worker parses it again).
    pub options: &'a str,
    pub format: &'a str,
    pub lens: Option<&'a str>,
    pub width: i32,
    pub height: i32,
    pub input_key: &'a str,
    /// The client's gyro log, stored beside the upload.
    pub gyro_key: Option<&'a str>,
    pub frames_total: Option<i64>,
}

/// A job a worker has claimed: what it needs to run it.
#[derive(Clone, Debug)]
pub struct Claim {
    pub id: String,
    /// Its tenant: the prefix of its objects.
    pub tenant: String,
    /// This claim's number (1, 2, ...): part of the claim's identity.
    pub attempt: i32,
    pub options: String,
    pub format: String,
    pub lens: Option<String>,
    pub width: i32,
    pub height: i32,
    pub input_key: String,
    /// The client's gyro log, beside the upload (removed with it).
    pub gyro_key: Option<String>,
    pub frames_total: Option<i64>,
}

/// How a worker's run of a job ended.
pub enum Outcome<'a> {
    Done {
        output_key: &'a str,
        telemetry_key: &'a str,
        frames: i64,
        metrics: &'a str,
        motion: &'a str,
    },
    Failed {
        error: &'a str,
    },
}

/// Jobs by state, for `/metrics`.
#[derive(Debug, Default)]
pub struct Counts {
    pub by_state: Vec<(String, i64)>,
    /// Claims beyond the first, summed over the jobs in the table.
    pub retries: i64,
}

/// The job table.
#[derive(Clone)]
pub struct Queue {
    pub(super) pool: PgPool,
}

fn secs(d: Duration) -> f64 {
    d.as_secs_f64()
}

impl Queue {
    /// Connects and brings the schema up to date, retrying a database that
    /// is not up yet for up to `patience` (containers start in any order).
    pub async fn connect(url: &str, patience: Duration) -> Result<Self, ClusterError> {
        let pool = PgPoolOptions::new()
            .max_connections(8)
            .acquire_timeout(ACQUIRE_TIMEOUT)
            .connect_lazy(url)
            .map_err(ClusterError::db("reading the --queue URL"))?;
        let queue = Self { pool };
        let start = std::time::Instant::now();
        let mut wait = Duration::from_millis(200);
        loop {
            match migrator().run(&queue.pool).await {
                Ok(()) => return Ok(queue),
                Err(e) => {
                    let e = ClusterError::from(e);
                    if !e.unreachable() || start.elapsed() + wait > patience {
                        return Err(e);
                    }
                    tracing::warn!(error = %e, "the job table's database is not reachable yet; retrying");
                    tokio::time::sleep(wait).await;
                    wait = (wait * 2).min(Duration::from_secs(3));
                }
            }
        }
    }

    /// Answers when the database does.
    pub async fn ping(&self) -> Result<(), ClusterError> {
        sqlx::query("SELECT 1")
            .execute(&self.pool)
            .await
            .map(|_| ())
            .map_err(ClusterError::db("checking the connection"))
    }

    pub async fn insert(&self, job: &NewJob<'_>) -> Result<JobRow, ClusterError> {
        let sql = format!(
            "INSERT INTO amc_jobs (id, options, format, lens, width, height, input_key, frames_total, tenant, gyro_key) \
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10) RETURNING {COLUMNS}"
        );
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(job.id)
            .bind(job.options)
            .bind(job.format)
            .bind(job.lens)
            .bind(job.width)
            .bind(job.height)
            .bind(job.input_key)
            .bind(job.frames_total)
            .bind(job.tenant)
            .bind(job.gyro_key)
            .fetch_one(&self.pool)
            .await
            .map_err(ClusterError::db("queueing a job"))?;
        JobRow::of(&row).map_err(ClusterError::db("reading a job"))
    }

    pub async fn get(&self, id: &str) -> Result<Option<JobRow>, ClusterError> {
        let sql = format!("SELECT {COLUMNS} FROM amc_jobs WHERE id = $1");
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(id)
            .fetch_optional(&self.pool)
            .await
            .map_err(ClusterError::db("reading a job"))?;
        row.as_ref()
            .map(JobRow::of)
            .transpose()
            .map_err(ClusterError::db("reading a job"))
    }

    /// Up to `limit` jobs of `tenant` (`None`: every tenant's) accepted
    /// before `before` (a `seq`; `None`: the newest), newest first, and
    /// whether there are more.
    pub async fn page(
        &self,
        tenant: Option<&str>,
        limit: usize,
        before: Option<i64>,
    ) -> Result<(Vec<JobRow>, bool), ClusterError> {
        let sql = format!(
            "SELECT {COLUMNS} FROM amc_jobs WHERE ($1::bigint IS NULL OR seq < $1) \
             AND ($3::text IS NULL OR tenant = $3) ORDER BY seq DESC LIMIT $2"
        );
        let rows = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(before)
            .bind(limit as i64 + 1)
            .bind(tenant)
            .fetch_all(&self.pool)
            .await
            .map_err(ClusterError::db("listing jobs"))?;
        let mut jobs = rows
            .iter()
            .map(JobRow::of)
            .collect::<Result<Vec<_>, _>>()
            .map_err(ClusterError::db("listing jobs"))?;
        let more = jobs.len() > limit;
        jobs.truncate(limit);
        Ok((jobs, more))
    }

    /// Jobs of `tenant` queued or running (its `--max-jobs-per-tenant`).
    pub async fn active(&self, tenant: &str) -> Result<i64, ClusterError> {
        sqlx::query_scalar(
            "SELECT count(*) FROM amc_jobs WHERE tenant = $1 AND state IN ('queued', 'running')",
        )
        .bind(tenant)
        .fetch_one(&self.pool)
        .await
        .map_err(ClusterError::db("counting a tenant's jobs"))
    }

    /// Cancels a queued or running job; `None` if it had already finished
    /// (or does not exist). The job's worker sees it at its next renewal.
    pub async fn cancel(&self, id: &str) -> Result<Option<JobRow>, ClusterError> {
        let sql = format!(
            "UPDATE amc_jobs SET state = 'cancelled', finished_at = now() \
             WHERE id = $1 AND state IN ('queued', 'running') RETURNING {COLUMNS}"
        );
        let row = sqlx::query(sqlx::AssertSqlSafe(sql))
            .bind(id)
            .fetch_optional(&self.pool)
            .await
            .map_err(ClusterError::db("cancelling a job"))?;
        row.as_ref()
            .map(JobRow::of)
            .transpose()
            .map_err(ClusterError::db("cancelling a job"))
    }

    /// Deletes a finished job's row; `remove_objects` runs first, inside
    /// the row's lock, so a failure leaves the row (and a later try) in place.
    pub async fn remove_finished<F, Fut>(
        &self,
        id: &str,
        remove_objects: F,
    ) -> Result<bool, ClusterError>
    where
        F: FnOnce(String, String) -> Fut,
        Fut: std::future::Future<Output = Result<(), ClusterError>>,
    {
        let mut tx = self
            .pool
            .begin()
            .await
            .map_err(ClusterError::db("removing a job"))?;
        let found = sqlx::query(
            "SELECT id, tenant FROM amc_jobs WHERE id = $1 \
             AND state IN ('done', 'failed', 'cancelled') FOR UPDATE",
        )
        .bind(id)
        .fetch_optional(&mut *tx)
        .await
        .map_err(ClusterError::db("removing a job"))?;
        let Some(found) = found else {
            return Ok(false);
        };
        let tenant: String = found
            .try_get("tenant")
            .map_err(ClusterError::db("removing a job"))?;
        remove_objects(id.to_string(), tenant).await?;
        sqlx::query("DELETE FROM amc_jobs WHERE id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await
            .map_err(ClusterError::db("removing a job"))?;
        tx.commit()
            .await
            .map_err(ClusterError::db("removing a job"))?;
        Ok(true)
    }

    /// Deletes up to `limit` jobs that finished more than `ttl` ago, each
    /// after `remove_objects(id)` succeeded for it. Rows another sweeper
    /// holds are skipped, so every replica and worker may sweep at once.
    pub async fn expire<F, Fut>(
        &self,
        ttl: Duration,
        limit: i64,
        remove_objects: F,
    ) -> Result<usize, ClusterError>
    where
        F: Fn(String, String) -> Fut,
        Fut: std::future::Future<Output = Result<(), ClusterError>>,
    {
        let mut tx = self
            .pool
            .begin()
            .await
            .map_err(ClusterError::db("expiring jobs"))?;
        let rows = sqlx::query(
            "SELECT id, tenant FROM amc_jobs WHERE finished_at < now() - make_interval(secs => $1) \
             AND state IN ('done', 'failed', 'cancelled') \
             AND (lease_until IS NULL OR lease_until < now()) \
             ORDER BY finished_at LIMIT $2 FOR UPDATE SKIP LOCKED",
        )
        .bind(secs(ttl))
        .bind(limit)
        .fetch_all(&mut *tx)
        .await
        .map_err(ClusterError::db("expiring jobs"))?;
        let mut removed = Vec::new();
        for row in &rows {
            let id: String = row
                .try_get("id")
                .map_err(ClusterError::db("expiring jobs"))?;
            let tenant: String = row
                .try_get("tenant")
                .map_err(ClusterError::db("expiring jobs"))?;
            match remove_objects(id.clone(), tenant).await {
                Ok(()) => removed.push(id),
                // Left for the next sweep; the others still go.
                Err(e) => {
                    tracing::warn!(job = %id, error = %e, "cannot remove an expired job's objects yet")
                }
            }
        }
        sqlx::query("DELETE FROM amc_jobs WHERE id = ANY($1)")
            .bind(&removed)
            .execute(&mut *tx)
            .await
            .map_err(ClusterError::db("expiring jobs"))?;
        tx.commit()
            .await
            .map_err(ClusterError::db("expiring jobs"))?;
        Ok(removed.len())
    }

    /// Jobs by state and the retries among them.
    pub async fn counts(&self) -> Result<Counts, ClusterError> {
        let rows = sqlx::query(
            "SELECT state, count(*) AS n, coalesce(sum(greatest(attempts - 1, 0)), 0)::bigint AS retries \
             FROM amc_jobs GROUP BY state",
        )
        .fetch_all(&self.pool)
        .await
        .map_err(ClusterError::db("counting jobs"))?;
        let mut counts = Counts::default();
        for row in &rows {
            let get = |r: &PgRow| -> Result<(String, i64, i64), sqlx::Error> {
                Ok((r.try_get("state")?, r.try_get("n")?, r.try_get("retries")?))
            };
            let (state, n, retries) = get(row).map_err(ClusterError::db("counting jobs"))?;
            counts.by_state.push((state, n));
            counts.retries += retries;
        }
        Ok(counts)
    }

    /// Claims the oldest job that is queued, or running under a lease that
    /// ran out (its worker died), and has had fewer than `max_attempts`
    /// claims. `None` when there is none.
    pub async fn claim(
        &self,
        worker: &str,
        lease: Duration,
        max_attempts: u32,
    ) -> Result<Option<Claim>, ClusterError> {
        let row = sqlx::query(
            "UPDATE amc_jobs j SET state = 'running', worker = $1, attempts = j.attempts + 1, \
                 lease_until = now() + make_interval(secs => $2), started_at = now() \
             FROM (SELECT id FROM amc_jobs \
                   WHERE (state = 'queued' OR (state = 'running' AND lease_until < now())) \
                     AND attempts < $3 \
                   ORDER BY seq LIMIT 1 FOR UPDATE SKIP LOCKED) c \
             WHERE j.id = c.id \
             RETURNING j.id, j.tenant, j.attempts, j.options, j.format, j.lens, j.width, j.height, \
                 j.input_key, j.frames_total, j.gyro_key",
        )
        .bind(worker)
        .bind(secs(lease))
        .bind(max_attempts as i32)
        .fetch_optional(&self.pool)
        .await
        .map_err(ClusterError::db("claiming a job"))?;
        let Some(row) = row else { return Ok(None) };
        let claim = |r: &PgRow| -> Result<Claim, sqlx::Error> {
            Ok(Claim {
                id: r.try_get("id")?,
                tenant: r.try_get("tenant")?,
                attempt: r.try_get("attempts")?,
                options: r.try_get("options")?,
                format: r.try_get("format")?,
                lens: r.try_get("lens")?,
                width: r.try_get("width")?,
                height: r.try_get("height")?,
                input_key: r.try_get("input_key")?,
                gyro_key: r.try_get("gyro_key")?,
                frames_total: r.try_get("frames_total")?,
            })
        };
        claim(&row)
            .map(Some)
            .map_err(ClusterError::db("claiming a job"))
    }

    /// Renews the claim's lease and records its progress (never lowering
    /// it: a retried job's progress does not go back). False when the job
    /// is no longer this claim's: cancelled, or given to another worker.
    pub async fn heartbeat(
        &self,
        claim: &Claim,
        worker: &str,
        frames_done: u64,
        lease: Duration,
    ) -> Result<bool, ClusterError> {
        let done = sqlx::query(
            "UPDATE amc_jobs SET lease_until = now() + make_interval(secs => $4), \
                 frames_done = greatest(frames_done, $5) \
             WHERE id = $1 AND attempts = $2 AND worker = $3 AND state = 'running'",
        )
        .bind(&claim.id)
        .bind(claim.attempt)
        .bind(worker)
        .bind(secs(lease))
        .bind(frames_done as i64)
        .execute(&self.pool)
        .await
        .map_err(ClusterError::db("renewing a lease"))?;
        Ok(done.rows_affected() == 1)
    }

    /// Records how the claim's run ended; false (and nothing written) when
    /// the job is no longer this claim's.
    pub async fn finish(
        &self,
        claim: &Claim,
        worker: &str,
        outcome: &Outcome<'_>,
    ) -> Result<bool, ClusterError> {
        let query = match outcome {
            Outcome::Done {
                output_key,
                telemetry_key,
                frames,
                metrics,
                motion,
            } => sqlx::query(
                "UPDATE amc_jobs SET state = 'done', finished_at = now(), worker = NULL, \
                     lease_until = NULL, output_key = $4, telemetry_key = $5, \
                     frames_done = $6, metrics = $7::jsonb, motion = $8::jsonb \
                 WHERE id = $1 AND attempts = $2 AND worker = $3 AND state = 'running'",
            )
            .bind(&claim.id)
            .bind(claim.attempt)
            .bind(worker)
            .bind(*output_key)
            .bind(*telemetry_key)
            .bind(*frames)
            .bind(*metrics)
            .bind(*motion),
            Outcome::Failed { error } => sqlx::query(
                "UPDATE amc_jobs SET state = 'failed', finished_at = now(), worker = NULL, \
                     lease_until = NULL, error = $4 \
                 WHERE id = $1 AND attempts = $2 AND worker = $3 AND state = 'running'",
            )
            .bind(&claim.id)
            .bind(claim.attempt)
            .bind(worker)
            .bind(*error),
        };
        let done = query
            .execute(&self.pool)
            .await
            .map_err(ClusterError::db("finishing a job"))?;
        Ok(done.rows_affected() == 1)
    }

    /// Lets go of a claim whose job was cancelled (or taken over): clears
    /// the lease so `DELETE` knows the worker has stopped.
    pub async fn release(&self, claim: &Claim, worker: &str) -> Result<(), ClusterError> {
        sqlx::query(
            "UPDATE amc_jobs SET worker = NULL, lease_until = NULL \
             WHERE id = $1 AND attempts = $2 AND worker = $3",
        )
        .bind(&claim.id)
        .bind(claim.attempt)
        .bind(worker)
        .execute(&self.pool)
        .await
        .map_err(ClusterError::db("releasing a job"))?;
        Ok(())
    }

    /// Puts a running claim back in the queue, not counting the attempt
    /// (the worker is shutting down; the job is not at fault).
    pub async fn hand_back(&self, claim: &Claim, worker: &str) -> Result<bool, ClusterError> {
        let done = sqlx::query(
            "UPDATE amc_jobs SET state = 'queued', worker = NULL, lease_until = NULL, \
                 attempts = attempts - 1, started_at = NULL \
             WHERE id = $1 AND attempts = $2 AND worker = $3 AND state = 'running'",
        )
        .bind(&claim.id)
        .bind(claim.attempt)
        .bind(worker)
        .execute(&self.pool)
        .await
        .map_err(ClusterError::db("handing a job back"))?;
        Ok(done.rows_affected() == 1)
    }

    /// Fails the running jobs whose lease ran out after their last allowed
    /// claim, saying why. Returns how many.
    pub async fn fail_abandoned(&self, max_attempts: u32) -> Result<u64, ClusterError> {
        let done = sqlx::query(
            "UPDATE amc_jobs SET state = 'failed', finished_at = now(), worker = NULL, \
                 lease_until = NULL, \
                 error = format('the job was tried %s times and each time its worker stopped \
                                 answering before it finished (lease expired); not retried', attempts) \
             WHERE state = 'running' AND lease_until < now() AND attempts >= $1",
        )
        .bind(max_attempts as i32)
        .execute(&self.pool)
        .await
        .map_err(ClusterError::db("failing abandoned jobs"))?;
        Ok(done.rows_affected())
    }
}
