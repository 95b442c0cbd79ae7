-- Control and integrated tracks: policy runs, their episode jobs and the episodes' results.
--
-- A policy submission's `body` (submissions table) is its endpoint JSON: url, bearer token (the
-- workers need it to call the policy, so it is stored), linked plans submission, the probe's
-- spec summary and the `reference` flag. Its scoring run is a `scoring_runs` row like any other;
-- the columns below say how far the run is and hold its track scores for ranking.

-- `active` until every job is done or failed, then `finished` (scores filled in the same
-- transaction as the last result) or `platform_failed` (no episode could run because of the
-- platform: such a submission does not use quota). Plan runs are scored at once: `finished`.
ALTER TABLE scoring_runs ADD COLUMN state TEXT NOT NULL DEFAULT 'finished'
    CHECK (state IN ('active', 'finished', 'platform_failed'));
-- Jobs queued for the run (0 for plan runs).
ALTER TABLE scoring_runs ADD COLUMN episodes_total INTEGER NOT NULL DEFAULT 0;
-- Most jobs of this run leased at once: the policy's announced max concurrency (0 = no limit).
ALTER TABLE scoring_runs ADD COLUMN max_concurrency INTEGER NOT NULL DEFAULT 0;
-- Track scores, NULL until finished or when not applicable. `p` may be +inf (EM = 0): SQLite
-- stores infinities in REAL columns and sorts them after every finite value.
ALTER TABLE scoring_runs ADD COLUMN sr REAL;
ALTER TABLE scoring_runs ADD COLUMN mse REAL;
ALTER TABLE scoring_runs ADD COLUMN m REAL;
ALTER TABLE scoring_runs ADD COLUMN p REAL;
ALTER TABLE scoring_runs ADD COLUMN finished_at INTEGER;

-- Concurrent-run quota and the reaper look runs up by state.
CREATE INDEX scoring_runs_state ON scoring_runs (state, submission_id);

-- One job per episode of a run. Claimed with a single UPDATE ... RETURNING; a lease that is not
-- extended by heartbeats expires and the reaper requeues the job (or fails it after
-- max_attempts). `attempt` counts leases, so a report from an earlier lease is recognisable.
CREATE TABLE jobs (
    id                INTEGER PRIMARY KEY AUTOINCREMENT,
    run_id            INTEGER NOT NULL REFERENCES scoring_runs(id),
    episode_key       TEXT    NOT NULL,      -- `dev-0007` (online) or `dev-0007/offline`
    spec              TEXT    NOT NULL,      -- JSON: EpisodeSpec + PolicyEndpoint as leased
    state             TEXT    NOT NULL DEFAULT 'queued'
                      CHECK (state IN ('queued', 'leased', 'done', 'failed', 'cancelled')),
    lease_owner       TEXT,                  -- worker_id of the current lease
    lease_expires_at  INTEGER,               -- Unix milliseconds, UTC
    attempt           INTEGER NOT NULL DEFAULT 0,
    max_attempts      INTEGER NOT NULL,
    last_error        TEXT,                  -- why the previous attempt did not finish
    created_at        INTEGER NOT NULL,
    updated_at        INTEGER NOT NULL,
    UNIQUE (run_id, episode_key)
);

CREATE INDEX jobs_state_id ON jobs (state, id);
CREATE INDEX jobs_run_state ON jobs (run_id, state);
CREATE INDEX jobs_state_lease ON jobs (state, lease_expires_at);

-- The outcome of one episode. The primary key makes results idempotent: a redelivered report
-- (`INSERT ... ON CONFLICT DO NOTHING`) never counts twice.
CREATE TABLE episode_results (
    run_id       INTEGER NOT NULL REFERENCES scoring_runs(id),
    episode_key  TEXT    NOT NULL,
    job_id       INTEGER NOT NULL REFERENCES jobs(id),
    mode         TEXT    NOT NULL CHECK (mode IN ('online', 'offline')),
    tasks        TEXT    NOT NULL,           -- JSON list: index, step, success, completion_time_s,
                                             -- failure_reason, mse, mse_samples
    failure      TEXT,                       -- set when the episode never ran (platform gave up)
    wall_ms      INTEGER NOT NULL,
    log_tail     TEXT    NOT NULL,           -- capped at 64 KiB
    attempt      INTEGER NOT NULL,
    worker_id    TEXT    NOT NULL,
    recorded_at  INTEGER NOT NULL,
    PRIMARY KEY (run_id, episode_key)
) WITHOUT ROWID;
