-- The privileged-information track (issue #25): a policy run whose policy asked for, and
-- received, privileged observations is ranked apart from standard runs on the control and
-- integrated boards. Each entry says which board it belongs to. Planning entries and every
-- entry made before this migration are `standard`. A team's best privileged entry takes
-- `entry` = -1 (its best standard entry keeps 0, reference runs their submission id), so both fit
-- the existing primary key. Additive only: submissions and results are untouched (the track of a
-- policy submission is `privileged_observations` in its stored body, absent = standard), and the
-- server rebuilds this table at start-up.
ALTER TABLE leaderboard_entries
    ADD COLUMN observations TEXT NOT NULL DEFAULT 'standard'
    CHECK (observations IN ('standard', 'privileged'));
