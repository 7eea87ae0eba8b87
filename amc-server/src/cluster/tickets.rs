//! The live tickets' table (`amc_tickets`, migration 0002): any replica
//! redeems a ticket another issued, exactly once (`DELETE ... RETURNING`).

use super::error::ClusterError;
use super::queue::Queue;
use std::time::Duration;

impl Queue {
    /// Stores a ticket's hash, bound to `tenant`, `roles` and the key's line.
    pub async fn insert_ticket(
        &self,
        hash: &[u8; 32],
        tenant: &str,
        roles: &str,
        key_line: Option<usize>,
        ttl: Duration,
    ) -> Result<(), ClusterError> {
        sqlx::query(
            "INSERT INTO amc_tickets (hash, tenant, roles, key_line, expires_at) \
             VALUES ($1, $2, $3, $4, now() + make_interval(secs => $5))",
        )
        .bind(&hash[..])
        .bind(tenant)
        .bind(roles)
        .bind(key_line.map(|k| k as i32))
        .bind(ttl.as_secs_f64())
        .execute(&self.pool)
        .await
        .map(|_| ())
        .map_err(ClusterError::db("issuing a live ticket"))
    }

    /// Removes the ticket and returns its (tenant, roles, key line) if it
    /// had not expired; `None` if unknown, used or expired.
    pub async fn redeem_ticket(
        &self,
        hash: &[u8; 32],
    ) -> Result<Option<(String, String, Option<usize>)>, ClusterError> {
        use sqlx::Row;
        let row = sqlx::query(
            "DELETE FROM amc_tickets WHERE hash = $1 \
             RETURNING tenant, roles, key_line, expires_at > now() AS fresh",
        )
        .bind(&hash[..])
        .fetch_optional(&self.pool)
        .await
        .map_err(ClusterError::db("redeeming a live ticket"))?;
        let Some(row) = row else { return Ok(None) };
        let read = |r: &sqlx::postgres::PgRow| -> Result<_, sqlx::Error> {
            let fresh: bool = r.try_get("fresh")?;
            let key: Option<i32> = r.try_get("key_line")?;
            Ok(fresh.then(|| {
                Ok::<_, sqlx::Error>((
                    r.try_get::<String, _>("tenant")?,
                    r.try_get::<String, _>("roles")?,
                    key.map(|k| k.max(0) as usize),
                ))
            }))
        };
        match read(&row).map_err(ClusterError::db("redeeming a live ticket"))? {
            Some(t) => t
                .map(Some)
                .map_err(ClusterError::db("redeeming a live ticket")),
            None => Ok(None),
        }
    }

    /// Removes expired tickets (the sweep).
    pub async fn expire_tickets(&self) -> Result<u64, ClusterError> {
        sqlx::query("DELETE FROM amc_tickets WHERE expires_at < now()")
            .execute(&self.pool)
            .await
            .map(|r| r.rows_affected())
            .map_err(ClusterError::db("expiring live tickets"))
    }
}
