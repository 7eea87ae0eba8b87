-- The job table of `amc serve --queue` and `amc worker`: one row a job.
-- A worker claims a queued row (or one whose lease expired) with
-- FOR UPDATE SKIP LOCKED, renews `lease_until` while it works and writes
-- its progress into `frames_done`; `attempts` counts claims.
CREATE TABLE amc_jobs (
    id            TEXT PRIMARY KEY CHECK (id ~ '^[0-9a-f]{32}$'),
    -- Order of acceptance: listing, cursors and the queue's order.
    seq           BIGINT GENERATED ALWAYS AS IDENTITY UNIQUE,
    state         TEXT NOT NULL DEFAULT 'queued'
                  CHECK (state IN ('queued', 'running', 'done', 'failed', 'cancelled')),
    created_at    TIMESTAMPTZ NOT NULL DEFAULT now(),
    started_at    TIMESTAMPTZ,
    finished_at   TIMESTAMPTZ,
    -- The request's query string, parsed again (and so checked again) by the worker.
    options       TEXT NOT NULL,
    format        TEXT NOT NULL,
    -- A lens file sent with the upload (multipart), as text.
    lens          TEXT,
    width         INTEGER NOT NULL,
    height        INTEGER NOT NULL,
    input_key     TEXT NOT NULL,
    frames_total  BIGINT,
    frames_done   BIGINT NOT NULL DEFAULT 0,
    attempts      INTEGER NOT NULL DEFAULT 0,
    worker        TEXT,
    lease_until   TIMESTAMPTZ,
    output_key    TEXT,
    telemetry_key TEXT,
    error         TEXT,
    metrics       JSONB,
    motion        JSONB
);

CREATE INDEX amc_jobs_queued ON amc_jobs (seq) WHERE state = 'queued';
CREATE INDEX amc_jobs_leases ON amc_jobs (lease_until) WHERE state = 'running';
CREATE INDEX amc_jobs_finished ON amc_jobs (finished_at) WHERE finished_at IS NOT NULL;
