-- Videos on demand (issue #26): workers upload each online episode's trace (gzipped JSON that
-- reproduces it bit for bit) instead of its video, and a video is rendered from the trace by a
-- worker when it is first asked for.
--
-- `episode_traces`: which stored trace file (`<video dir>/traces/<aa>/<sha256>.json.gz`) belongs
-- to which (run, episode). Identical traces (a deterministic policy run twice) share a file; a
-- file is deleted once no row names it. Rows go with the videos' retention sweep.
CREATE TABLE episode_traces (
    run_id      INTEGER NOT NULL REFERENCES scoring_runs(id),
    episode_key TEXT    NOT NULL,
    sha256      TEXT    NOT NULL,
    bytes       INTEGER NOT NULL,
    created_at  INTEGER NOT NULL,      -- Unix milliseconds, UTC
    PRIMARY KEY (run_id, episode_key)
);
CREATE INDEX episode_traces_sha256 ON episode_traces (sha256);
CREATE INDEX episode_traces_created_at ON episode_traces (created_at);

-- One render of an episode's video from its trace: queued when the video is asked for, leased
-- to a worker only while no evaluation job waits, `done` when its video is uploaded (the video
-- row in `episode_videos` is then the episode's), `failed` with the reason the episode shows
-- (the replay disagreed with the stored result, say). A lease that is not extended expires and
-- the reaper queues the render again; after `max_attempts` leases it fails. `trace_sha256` keys
-- the render by what it replays, so a request for the same trace reuses a finished video.
CREATE TABLE video_renders (
    id               INTEGER PRIMARY KEY AUTOINCREMENT,
    run_id           INTEGER NOT NULL REFERENCES scoring_runs(id),
    episode_key      TEXT    NOT NULL,
    trace_sha256     TEXT    NOT NULL,
    state            TEXT    NOT NULL DEFAULT 'queued'
                     CHECK (state IN ('queued', 'leased', 'done', 'failed')),
    progress         REAL    NOT NULL DEFAULT 0,   -- 0..=1, from the worker's heartbeats
    error            TEXT,                         -- failed: why there is no video
    video_sha256     TEXT,                         -- done: the video file made
    lease_owner      TEXT,
    lease_expires_at INTEGER,                      -- Unix milliseconds, UTC
    attempt          INTEGER NOT NULL DEFAULT 0,
    created_at       INTEGER NOT NULL,
    updated_at       INTEGER NOT NULL,
    UNIQUE (run_id, episode_key)
);
CREATE INDEX video_renders_state_id ON video_renders (state, id);
CREATE INDEX video_renders_trace ON video_renders (trace_sha256, state);
CREATE INDEX video_renders_created_at ON video_renders (created_at);
