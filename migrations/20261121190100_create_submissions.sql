-- Submissions are immutable: what a team uploaded, as uploaded. Scores live in scoring_runs so
-- that rescoring adds rows instead of rewriting history.
CREATE TABLE submissions (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    team_id     INTEGER NOT NULL REFERENCES teams(id),
    split       TEXT    NOT NULL CHECK (split IN ('dev', 'test')),
    kind        TEXT    NOT NULL CHECK (kind IN ('plans', 'policy')),
    body        TEXT    NOT NULL,          -- plans: the JSON Lines file; policy: endpoint JSON
    created_at  INTEGER NOT NULL           -- Unix milliseconds, UTC
);

-- Quota checks count a team's submissions per split since a point in time.
CREATE INDEX submissions_team_split_created ON submissions (team_id, split, created_at);
CREATE INDEX submissions_split_kind ON submissions (split, kind);

-- One row per scoring of a submission (first scoring, every rescore, later: each policy run).
CREATE TABLE scoring_runs (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    submission_id   INTEGER NOT NULL REFERENCES submissions(id),
    scorer_version  TEXT    NOT NULL,
    created_at      INTEGER NOT NULL,      -- Unix milliseconds, UTC
    em              REAL,                  -- planning track; NULL when not applicable
    scores          TEXT    NOT NULL       -- every score as a JSON object ({"em": 0.83})
);

CREATE INDEX scoring_runs_submission ON scoring_runs (submission_id, id);

-- Per-instruction outcome of a run: what a participant sees on the submission page.
CREATE TABLE instruction_results (
    run_id          INTEGER NOT NULL REFERENCES scoring_runs(id),
    instruction_id  TEXT    NOT NULL,
    present         INTEGER NOT NULL,      -- 1 if the file had a plan for it
    correct_steps   INTEGER NOT NULL,
    total_steps     INTEGER NOT NULL,
    PRIMARY KEY (run_id, instruction_id)
) WITHOUT ROWID;
