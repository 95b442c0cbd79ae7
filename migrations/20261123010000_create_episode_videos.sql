-- Episode videos (issue #15): which stored file shows which (run, episode). The MP4 itself is on
-- disk under the server's video directory, named by its sha256 (`<aa>/<sha256>.mp4`), so
-- identical bytes are stored once and may be linked from several rows. A repeated upload of the
-- same (run, episode) replaces the link. Rows older than `[video] retention_days` are deleted by
-- the periodic sweep, and a file no row links any more is deleted with them.
CREATE TABLE episode_videos (
    run_id      INTEGER NOT NULL REFERENCES scoring_runs(id),
    episode_key TEXT    NOT NULL,
    sha256      TEXT    NOT NULL,
    bytes       INTEGER NOT NULL,
    created_at  INTEGER NOT NULL,      -- Unix milliseconds, UTC
    PRIMARY KEY (run_id, episode_key)
);
CREATE INDEX episode_videos_sha256 ON episode_videos (sha256);
CREATE INDEX episode_videos_created_at ON episode_videos (created_at);
