-- `scoring_runs.scores` (every score as a JSON object) was written and never read: the scores
-- live in their own columns (em, sr, mse, m, p), which the leaderboard sorts on. Dropping it
-- keeps one place for a run's scores; existing rows keep every score in those columns.
ALTER TABLE scoring_runs DROP COLUMN scores;
