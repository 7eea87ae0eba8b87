-- Tenants (`amc serve --auth-keys`): every job belongs to the tenant of the
-- key that submitted it; jobs from before keys existed belong to `local`
-- (the tenant of a service without keys). Listings are per tenant.
ALTER TABLE amc_jobs ADD COLUMN tenant TEXT NOT NULL DEFAULT 'local'
    CHECK (tenant ~ '^[A-Za-z0-9_.-]{1,64}$');
CREATE INDEX amc_jobs_tenant ON amc_jobs (tenant, seq);

-- Live tickets (`POST /live/ticket`): single-use, short-lived, bound to a
-- key's tenant and roles; kept as the SHA-256 of the ticket, so that any
-- replica can redeem one exactly once.
CREATE TABLE amc_tickets (
    hash       BYTEA PRIMARY KEY CHECK (length(hash) = 32),
    tenant     TEXT NOT NULL,
    roles      TEXT NOT NULL,
    key_line   INTEGER,
    expires_at TIMESTAMPTZ NOT NULL
);
CREATE INDEX amc_tickets_expiry ON amc_tickets (expires_at);
