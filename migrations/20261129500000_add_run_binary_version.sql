-- Results cards (docs/reference/leaderboard.md#results-cards): the version of the kitchen-r
-- server that queued a policy run or scored a plan run (a rescore: the one that rescored), so a
-- published row names the code it came from. NULL for every run made before this migration,
-- which the boards show as "unknown". Additive only.
ALTER TABLE scoring_runs ADD COLUMN binary_version TEXT;
