-- The grasp mode (issue #27): how the gripper held objects in a policy run's episodes, chosen by
-- the organiser (`[control] grasp` in the server config) and part of what a control score means.
-- Every run made before this migration ran the abstract grasp, the only mode there was. A rescore
-- copies its source run's mode; plan runs carry the default and never show it.
ALTER TABLE scoring_runs
    ADD COLUMN grasp_mode TEXT NOT NULL DEFAULT 'abstract'
    CHECK (grasp_mode IN ('abstract', 'physical'));
-- The boards rank runs of one grasp mode together (like the observation tracks): each entry
-- says the mode of the run it ranks. A team's best entry per mode takes `entry` 0 / -1 (standard
-- / privileged) in the abstract mode and -2 / -3 in the physical mode, so all fit the existing
-- primary key. Additive only; the server rebuilds this table at start-up.
ALTER TABLE leaderboard_entries
    ADD COLUMN grasp_mode TEXT NOT NULL DEFAULT 'abstract'
    CHECK (grasp_mode IN ('abstract', 'physical'));
