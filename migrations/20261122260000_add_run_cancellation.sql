-- no-transaction
-- An organiser may cancel a policy run (issue #13, the organiser's console): its open jobs
-- become `cancelled`, and the run gets its own state `cancelled` with who cancelled it and when.
-- A cancelled run, like a `platform_failed` one, uses no quota and ranks nowhere.
--
-- `scoring_runs.state` has a CHECK constraint, which SQLite cannot alter, so the table is rebuilt
-- (SQLite's documented 12-step procedure: https://sqlite.org/lang_altertable.html#otheralter).
-- Other tables reference scoring_runs, so foreign keys must be off while the old table is dropped,
-- and that pragma is a no-op inside a transaction: this migration opens its own transaction
-- (the `no-transaction` line above tells sqlx not to), checks the foreign keys before committing,
-- and turns them back on. Re-running it after a crash between its commit and sqlx's bookkeeping
-- rebuilds the table again to the same result. Every existing row keeps its id, values and
-- state.
PRAGMA foreign_keys = OFF;
BEGIN IMMEDIATE;
CREATE TABLE scoring_runs_rebuilt (
    id                  INTEGER PRIMARY KEY AUTOINCREMENT,
    submission_id       INTEGER NOT NULL REFERENCES submissions(id),
    scorer_version      TEXT    NOT NULL,
    created_at          INTEGER NOT NULL,
    em                  REAL,
    state               TEXT    NOT NULL DEFAULT 'finished'
                        CHECK (state IN ('active', 'finished', 'platform_failed', 'cancelled')),
    episodes_total      INTEGER NOT NULL DEFAULT 0,
    max_concurrency     INTEGER NOT NULL DEFAULT 0,
    sr                  REAL,
    mse                 REAL,
    m                   REAL,
    p                   REAL,
    finished_at         INTEGER,
    source_run_id       INTEGER REFERENCES scoring_runs(id),
    needs_resimulation  INTEGER NOT NULL DEFAULT 0,
    instructions_z      BLOB,
    -- Set together with state `cancelled`: when (Unix ms) and by whom (`organiser`).
    cancelled_at        INTEGER,
    cancelled_by        TEXT
);
INSERT INTO scoring_runs_rebuilt (id, submission_id, scorer_version, created_at, em, state,
        episodes_total, max_concurrency, sr, mse, m, p, finished_at, source_run_id,
        needs_resimulation, instructions_z)
    SELECT id, submission_id, scorer_version, created_at, em, state, episodes_total,
           max_concurrency, sr, mse, m, p, finished_at, source_run_id, needs_resimulation,
           instructions_z
    FROM scoring_runs;
-- The copy's sequence is its largest id; keep the old one when larger (no id is ever reused).
UPDATE sqlite_sequence
    SET seq = MAX(seq, (SELECT seq FROM sqlite_sequence WHERE name = 'scoring_runs'))
    WHERE name = 'scoring_runs_rebuilt'
      AND EXISTS (SELECT 1 FROM sqlite_sequence WHERE name = 'scoring_runs');
INSERT INTO sqlite_sequence (name, seq)
    SELECT 'scoring_runs_rebuilt', seq FROM sqlite_sequence WHERE name = 'scoring_runs'
      AND NOT EXISTS (SELECT 1 FROM sqlite_sequence WHERE name = 'scoring_runs_rebuilt');
DROP TABLE scoring_runs;
ALTER TABLE scoring_runs_rebuilt RENAME TO scoring_runs;
CREATE INDEX scoring_runs_submission ON scoring_runs (submission_id, id);
CREATE INDEX scoring_runs_state ON scoring_runs (state, submission_id);
COMMIT;
PRAGMA foreign_keys = ON;
