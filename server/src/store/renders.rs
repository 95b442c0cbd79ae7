//! Video renders' rows (`video_renders`; docs/contest/video.md): a queue of its own beside `jobs`,
//! leased to workers only when no evaluation job waits (`crate::service::renders`).

use sqlx::sqlite::SqlitePool;

/// One render's state as an episode shows it.
#[derive(Debug, Clone, PartialEq, sqlx::FromRow)]
pub(crate) struct RenderRow {
    pub id: i64,
    pub episode_key: String,
    pub trace_sha256: String,
    pub state: String,
    pub progress: f64,
    pub error: Option<String>,
    pub video_sha256: Option<String>,
    /// Queued: why it waits (no room for its video).
    pub waiting: Option<String>,
}

/// The render of `(run, key)`, if one was ever asked for.
pub(crate) async fn render(pool: &SqlitePool, run: i64, key: &str) -> sqlx::Result<Option<RenderRow>> {
    sqlx::query_as(
        "SELECT id, episode_key, trace_sha256, state, progress, error, video_sha256, waiting
         FROM video_renders WHERE run_id = ? AND episode_key = ?",
    )
    .bind(run)
    .bind(key)
    .fetch_optional(pool)
    .await
}

/// Every render of `run`.
pub(crate) async fn of_run(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<RenderRow>> {
    sqlx::query_as(
        "SELECT id, episode_key, trace_sha256, state, progress, error, video_sha256, waiting
         FROM video_renders WHERE run_id = ?",
    )
    .bind(run)
    .fetch_all(pool)
    .await
}

/// Queue a render of `(run, key)` from the trace `trace`: a new row, or an old one (done but its
/// video gone since, or of another trace) queued again. A queued or leased render stays as it
/// is ([`promote`] moves a queued pre-render someone asks for ahead), and so does a failed one
/// of the same trace (its replay would disagree again).
pub(crate) async fn request(
    pool: &SqlitePool,
    run: i64,
    key: &str,
    trace: &str,
    now: i64,
    prerender: bool,
) -> sqlx::Result<()> {
    sqlx::query(
        "INSERT INTO video_renders (run_id, episode_key, trace_sha256, created_at, updated_at, prerender)
         VALUES (?1, ?2, ?3, ?4, ?4, ?5)
         ON CONFLICT (run_id, episode_key) DO UPDATE SET state = 'queued', progress = 0,
             error = NULL, video_sha256 = NULL, trace_sha256 = excluded.trace_sha256,
             waiting = NULL, not_before = 0, waits = 0,
             attempt = 0, updated_at = excluded.updated_at, prerender = excluded.prerender
         WHERE state = 'done' OR (state = 'failed' AND trace_sha256 <> excluded.trace_sha256)",
    )
    .bind(run)
    .bind(key)
    .bind(trace)
    .bind(now)
    .bind(prerender)
    .execute(pool)
    .await?;
    Ok(())
}

/// Someone asked for the video of `(run, key)`: a pre-render of it is now an asked-for render.
pub(crate) async fn promote(pool: &SqlitePool, run: i64, key: &str) -> sqlx::Result<()> {
    sqlx::query(
        "UPDATE video_renders SET prerender = 0 WHERE run_id = ? AND episode_key = ? AND prerender = 1",
    )
    .bind(run)
    .bind(key)
    .execute(pool)
    .await?;
    Ok(())
}

/// A video some finished render made from the trace `trace` (the same trace, the same video).
pub(crate) async fn rendered(pool: &SqlitePool, trace: &str) -> sqlx::Result<Option<String>> {
    sqlx::query_scalar(
        "SELECT video_sha256 FROM video_renders WHERE trace_sha256 = ? AND state = 'done'
         AND video_sha256 IS NOT NULL ORDER BY updated_at DESC LIMIT 1",
    )
    .bind(trace)
    .fetch_optional(pool)
    .await
}

/// Whether any render may be leased at `now`.
pub(crate) async fn any_queued(pool: &SqlitePool, now: i64) -> sqlx::Result<bool> {
    sqlx::query_scalar(
        "SELECT EXISTS (SELECT 1 FROM video_renders WHERE state = 'queued' AND not_before <= ?)",
    )
    .bind(now)
    .fetch_one(pool)
    .await
}

/// A claimed render: what the worker needs to find its trace and check its replay.
#[derive(Debug, Clone, sqlx::FromRow)]
pub(crate) struct Claimed {
    pub id: i64,
    pub attempt: i64,
    pub run_id: i64,
    pub episode_key: String,
    pub trace_sha256: String,
    pub lease_expires_at: i64,
}

/// Lease the oldest queued render someone asked for, else the oldest pre-render, to `owner`
/// until `until`, unless an evaluation job is queued (checked in the same statement, so a job
/// queued meanwhile wins).
pub(crate) async fn claim(
    pool: &SqlitePool,
    owner: &str,
    now: i64,
    until: i64,
) -> sqlx::Result<Option<Claimed>> {
    sqlx::query_as(
        "UPDATE video_renders SET state = 'leased', lease_owner = ?1, lease_expires_at = ?2,
                attempt = attempt + 1, updated_at = ?3
         WHERE id = (SELECT id FROM video_renders WHERE state = 'queued' AND not_before <= ?3
                     ORDER BY prerender, id LIMIT 1)
           AND NOT EXISTS (SELECT 1 FROM jobs WHERE state = 'queued')
         RETURNING id, attempt, run_id, episode_key, trace_sha256, lease_expires_at",
    )
    .bind(owner)
    .bind(until)
    .bind(now)
    .fetch_optional(pool)
    .await
}

/// Extend a render lease held by `(id, attempt, owner)` and record its progress; `None` when
/// that lease is not held.
pub(crate) async fn heartbeat(
    pool: &SqlitePool,
    lease: Lease<'_>,
    until: i64,
    progress: f64,
    now: i64,
) -> sqlx::Result<Option<i64>> {
    sqlx::query_scalar(
        "UPDATE video_renders SET lease_expires_at = ?1, progress = MAX(progress, ?2), updated_at = ?3
         WHERE id = ?4 AND attempt = ?5 AND lease_owner = ?6 AND state = 'leased'
         RETURNING lease_expires_at",
    )
    .bind(until)
    .bind(progress.clamp(0.0, 1.0))
    .bind(now)
    .bind(lease.id)
    .bind(lease.attempt)
    .bind(lease.owner)
    .fetch_optional(pool)
    .await
}

/// A render lease as a worker names it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Lease<'a> {
    pub id: i64,
    pub attempt: i64,
    pub owner: &'a str,
}

/// The held render lease `(id, attempt)` of `(run, key)` (a video upload names it): the owner.
pub(crate) async fn held(
    pool: &SqlitePool,
    id: i64,
    attempt: i64,
    run: i64,
    key: &str,
) -> sqlx::Result<bool> {
    let found: Option<i64> = sqlx::query_scalar(
        "SELECT 1 FROM video_renders WHERE id = ? AND attempt = ? AND run_id = ? AND episode_key = ?
         AND state = 'leased'",
    )
    .bind(id)
    .bind(attempt)
    .bind(run)
    .bind(key)
    .fetch_optional(pool)
    .await?;
    Ok(found.is_some())
}

/// The render lease `lease` when it is held: which episode and which trace it renders.
pub(crate) async fn leased(pool: &SqlitePool, lease: Lease<'_>) -> sqlx::Result<Option<Claimed>> {
    sqlx::query_as(
        "SELECT id, attempt, run_id, episode_key, trace_sha256, lease_expires_at FROM video_renders
         WHERE id = ? AND attempt = ? AND lease_owner = ? AND state = 'leased'",
    )
    .bind(lease.id)
    .bind(lease.attempt)
    .bind(lease.owner)
    .fetch_optional(pool)
    .await
}

/// The render lease `(id, attempt)` found no room for its video: queued again, not before
/// `not_before` (the pause doubling with each wait, `pause_ms` the first), with `why`; the
/// lease does not count as an attempt. `false` when the lease is not held.
pub(crate) async fn wait(
    pool: &SqlitePool,
    id: i64,
    attempt: i64,
    why: &str,
    now: i64,
    pause_ms: i64,
) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "UPDATE video_renders SET state = 'queued', waiting = ?1, lease_owner = NULL,
                lease_expires_at = NULL, progress = 0, attempt = attempt - 1,
                not_before = ?2 + MIN(?3 << MIN(waits, 6), 3600000), waits = waits + 1, updated_at = ?2
         WHERE id = ?4 AND attempt = ?5 AND state = 'leased'",
    )
    .bind(why)
    .bind(now)
    .bind(pause_ms)
    .bind(id)
    .bind(attempt)
    .execute(pool)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// The render `(id, attempt)` made the video `video`.
pub(crate) async fn done(
    pool: &SqlitePool,
    id: i64,
    attempt: i64,
    video: &str,
    now: i64,
) -> sqlx::Result<()> {
    sqlx::query(
        "UPDATE video_renders SET state = 'done', progress = 1, video_sha256 = ?1, lease_owner = NULL,
                lease_expires_at = NULL, updated_at = ?2, waiting = NULL
         WHERE id = ?3 AND attempt = ?4 AND state = 'leased'",
    )
    .bind(video)
    .bind(now)
    .bind(id)
    .bind(attempt)
    .execute(pool)
    .await?;
    Ok(())
}

/// A render finished at once from another render's video of the same trace.
pub(crate) async fn reused(
    pool: &SqlitePool,
    run: i64,
    key: &str,
    video: &str,
    now: i64,
) -> sqlx::Result<()> {
    sqlx::query(
        "UPDATE video_renders SET state = 'done', progress = 1, video_sha256 = ?1, updated_at = ?2
         WHERE run_id = ?3 AND episode_key = ?4 AND state = 'queued'",
    )
    .bind(video)
    .bind(now)
    .bind(run)
    .bind(key)
    .execute(pool)
    .await?;
    Ok(())
}

/// The render lease failed with `error`; `false` when it is not held.
pub(crate) async fn fail(pool: &SqlitePool, lease: Lease<'_>, error: &str, now: i64) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "UPDATE video_renders SET state = 'failed', error = ?1, lease_owner = NULL,
                lease_expires_at = NULL, updated_at = ?2
         WHERE id = ?3 AND attempt = ?4 AND lease_owner = ?5 AND state = 'leased'",
    )
    .bind(error)
    .bind(now)
    .bind(lease.id)
    .bind(lease.attempt)
    .bind(lease.owner)
    .execute(pool)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// Queue again the renders whose lease ended before `now`, failing those leased `max_attempts`
/// times already. Returns how many were queued again.
pub(crate) async fn reap(pool: &SqlitePool, now: i64, max_attempts: i64) -> sqlx::Result<u64> {
    // A read first: the reaper runs every few seconds and must not take the write lock for nothing.
    let expired: bool = sqlx::query_scalar(
        "SELECT EXISTS (SELECT 1 FROM video_renders WHERE state = 'leased' AND lease_expires_at < ?)",
    )
    .bind(now)
    .fetch_one(pool)
    .await?;
    if !expired {
        return Ok(0);
    }
    sqlx::query(
        "UPDATE video_renders SET state = 'failed', lease_owner = NULL, lease_expires_at = NULL,
                error = 'the render was tried ' || attempt || CASE WHEN attempt = 1 THEN ' time' ELSE ' times' END
                    || ' and no worker finished it within its lease: the last, '
                    || COALESCE(lease_owner, 'a worker') || ', stopped at ' || CAST(ROUND(progress * 100) AS INTEGER)
                    || ' % (killed, out of memory, or cut off from the server; its log says which)',
                updated_at = ?1
         WHERE state = 'leased' AND lease_expires_at < ?1 AND attempt >= ?2",
    )
    .bind(now)
    .bind(max_attempts)
    .execute(pool)
    .await?;
    let requeued = sqlx::query(
        "UPDATE video_renders SET state = 'queued', lease_owner = NULL, lease_expires_at = NULL,
                progress = 0, updated_at = ?1
         WHERE state = 'leased' AND lease_expires_at < ?1",
    )
    .bind(now)
    .execute(pool)
    .await?;
    Ok(requeued.rows_affected())
}

/// The tasks the server stored as `(run, key)`'s result (what a replay must reproduce).
pub(crate) async fn stored_tasks(
    pool: &SqlitePool,
    run: i64,
    key: &str,
) -> sqlx::Result<Option<Vec<crate::episodes::TaskOutcome>>> {
    let tasks: Option<sqlx::types::Json<Vec<crate::episodes::TaskOutcome>>> =
        sqlx::query_scalar("SELECT tasks FROM episode_results WHERE run_id = ? AND episode_key = ?")
            .bind(run)
            .bind(key)
            .fetch_optional(pool)
            .await?;
    Ok(tasks.map(|t| t.0))
}
