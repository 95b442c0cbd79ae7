-- Storage per plan submission (issue #12: 32 KiB for a 163-line dev file). Plan files are kept
-- zstd-compressed in `body_z` (with `body` left empty), and a run's per-instruction results as
-- one zstd-compressed JSON array in `scoring_runs.instructions_z` instead of a row each in
-- `instruction_results`. The server converts rows written before this migration at start-up
-- (server/src/store/compact.rs), in batches, before it serves; nothing is lost or rescored.
ALTER TABLE submissions ADD COLUMN body_z BLOB;
ALTER TABLE scoring_runs ADD COLUMN instructions_z BLOB;
