-- Verification of policy runs (issue #42): `kitchen-r admin verify RUN` replays every stored
-- trace of a run bit for bit on the organiser's machine and records the verdict here, one row per
-- run (a later verification replaces it). `verdict` is `verified` when every episode's replay
-- agreed with its trace and with the stored result, `unverified` when any disagreed or had no
-- trace to replay; the organiser's console shows it. `disagreements` is a JSON list of
-- `{"episode", "why"}`. Additive: runs never verified have no row.
CREATE TABLE run_verifications (
    run_id         INTEGER PRIMARY KEY REFERENCES scoring_runs(id),
    verdict        TEXT    NOT NULL CHECK (verdict IN ('verified', 'unverified')),
    episodes       INTEGER NOT NULL,      -- episodes with a stored result to replay
    replayed       INTEGER NOT NULL,      -- of which replayed and agreeing
    disagreements  TEXT    NOT NULL,      -- JSON list of {"episode", "why"}
    binary_version TEXT    NOT NULL,      -- the kitchen-r that replayed them
    verified_at    INTEGER NOT NULL       -- Unix milliseconds, UTC
);
