-- Traces inside the storage budgets (issue #37): an episode trace counts against its team's and
-- the total budget (`[video] team_max_bytes`, `total_max_bytes`) as a video does. A trace
-- removed to keep a budget keeps its row, with no file and a `note` the episode shows (its video
-- can no longer be rendered); rows without a note are the stored traces. Traces of a test-split
-- run of a ranked submission are never removed (the organiser verifies a ranked run from them).
ALTER TABLE episode_traces ADD COLUMN team_id INTEGER REFERENCES teams(id);
ALTER TABLE episode_traces ADD COLUMN note TEXT;  -- NULL: the file is stored

UPDATE episode_traces SET team_id = (
    SELECT s.team_id FROM scoring_runs r JOIN submissions s ON s.id = r.submission_id
    WHERE r.id = episode_traces.run_id
);

CREATE INDEX episode_traces_team_stored ON episode_traces (team_id, created_at, bytes)
    WHERE note IS NULL;
CREATE INDEX episode_traces_stored ON episode_traces (created_at, bytes) WHERE note IS NULL;

-- A render whose video found no room (every team within its fair share of a full total, or its
-- team's budget full of protected traces) waits queued: `waiting` says why (the episode shows
-- it), `not_before` (Unix ms) when it may be leased again, `waits` how often it has waited (the
-- pause doubles each time, up to an hour). Waiting never counts as an attempt.
ALTER TABLE video_renders ADD COLUMN waiting TEXT;
ALTER TABLE video_renders ADD COLUMN not_before INTEGER NOT NULL DEFAULT 0;
ALTER TABLE video_renders ADD COLUMN waits INTEGER NOT NULL DEFAULT 0;
