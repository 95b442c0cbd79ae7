-- The leaderboards, maintained instead of recomputed. One row per ranked entry: a team's best
-- submission on a track and split (`entry` = 0), or one organiser reference run (`entry` = its
-- submission id). Every write that adds a scoring run or changes a run's state refreshes the
-- entries of that submission's team in the same transaction (server/src/store/board.rs), so a
-- read is one indexed scan of at most a few rows per team. The server rebuilds the whole table
-- at start-up, so databases from before this table (and any hand repair) come out consistent.
CREATE TABLE leaderboard_entries (
    track          TEXT    NOT NULL CHECK (track IN ('planning', 'control', 'integrated')),
    split          TEXT    NOT NULL CHECK (split IN ('dev', 'test')),
    team_id        INTEGER NOT NULL REFERENCES teams(id),
    entry          INTEGER NOT NULL,
    submission_id  INTEGER NOT NULL REFERENCES submissions(id),
    -- Ranking keys: k1 descending, then k2 ascending, NULLs last (EM; SR then MSE; M then P).
    k1             REAL,
    k2             REAL,
    created_at     INTEGER NOT NULL,
    state          TEXT,                   -- the latest run's state (policy tracks)
    em             REAL,
    sr             REAL,
    mse            REAL,
    m              REAL,
    p              REAL,
    baseline       INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (track, split, team_id, entry)
) WITHOUT ROWID;
