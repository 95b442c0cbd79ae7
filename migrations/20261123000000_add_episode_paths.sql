-- Where the robot went (issue #15): an online episode's base and key-object paths, each task's
-- goal and where it ended, as a worker reported them, for the episode's top-down plot. zstd-
-- compressed JSON (see `server/src/store/packed.rs`); NULL for offline episodes, results from
-- workers that do not report a path, and results recorded before this column existed.
ALTER TABLE episode_results ADD COLUMN path_z BLOB;
