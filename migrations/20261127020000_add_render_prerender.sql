-- Pre-rendered videos (issue #26, `[video] prerender`): a render queued because its episode
-- failed a task, before anyone asked. Workers take asked-for renders first (ORDER BY prerender,
-- id); asking for a queued pre-render turns it into an asked-for one.
ALTER TABLE video_renders ADD COLUMN prerender INTEGER NOT NULL DEFAULT 0;
CREATE INDEX video_renders_queue ON video_renders (state, prerender, id);
