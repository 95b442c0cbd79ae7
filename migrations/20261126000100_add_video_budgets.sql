-- Video storage budgets (issue 23; `[video] team_max_bytes`, `total_max_bytes`): an upload past a
-- budget removes the oldest videos first. A removed video keeps its row, with no file and a
-- `note` saying why, so its episode shows the reason where the video was. Rows without a note
-- are the stored videos; their `bytes` are what the budgets count (per row: a file linked twice
-- counts twice). `team_id` is the team of the row's run, kept here so a team's stored bytes and
-- its oldest video are one indexed read.
ALTER TABLE episode_videos ADD COLUMN team_id INTEGER REFERENCES teams(id);
ALTER TABLE episode_videos ADD COLUMN note TEXT;  -- NULL: the file is stored

UPDATE episode_videos SET team_id = (
    SELECT s.team_id FROM scoring_runs r JOIN submissions s ON s.id = r.submission_id
    WHERE r.id = episode_videos.run_id
);

-- Only stored videos count and are evicted; the partial indexes cover the sums and the order.
CREATE INDEX episode_videos_team_stored ON episode_videos (team_id, created_at, bytes)
    WHERE note IS NULL;
CREATE INDEX episode_videos_stored ON episode_videos (created_at, bytes) WHERE note IS NULL;
