//! Episode videos' rows (`episode_videos`): which stored file (by sha256) shows which
//! (run, episode), and the retention sweep's deletes (the budgets' evictions: `super::budget`). The files are
//! `crate::service::videos`'.
//!
//! A row with a `note` is a video removed to keep a budget: it has no file any more and says
//! why. Everything that counts, serves or keeps files reads only rows without one ("stored").

use sqlx::sqlite::SqlitePool;

/// The job a video upload names is that episode's, its result reported with that attempt.
pub(crate) async fn reported_job(
    pool: &SqlitePool,
    job: i64,
    attempt: u32,
    run: i64,
    key: &str,
) -> sqlx::Result<bool> {
    let found: Option<i64> = sqlx::query_scalar(
        "SELECT 1 FROM jobs j JOIN episode_results r ON r.run_id = j.run_id AND r.episode_key = j.episode_key
         WHERE j.id = ? AND j.attempt = ? AND j.run_id = ? AND j.episode_key = ? AND j.state = 'done'",
    )
    .bind(job)
    .bind(i64::from(attempt))
    .bind(run)
    .bind(key)
    .fetch_optional(pool)
    .await?;
    Ok(found.is_some())
}

/// The team whose run `run` is, and its name.
pub(crate) async fn team_of_run(pool: &SqlitePool, run: i64) -> sqlx::Result<Option<(i64, String)>> {
    sqlx::query_as(
        "SELECT t.id, t.name FROM scoring_runs r JOIN submissions s ON s.id = r.submission_id
         JOIN teams t ON t.id = s.team_id WHERE r.id = ?",
    )
    .bind(run)
    .fetch_optional(pool)
    .await
}

/// Link `(run, key)` of `team` to the file `sha256`, replacing an earlier link or note.
/// Returns the file the replaced link named when no stored row names it any more.
pub(crate) async fn link(
    pool: &SqlitePool,
    row: Row<'_>,
    sha256: &str,
    bytes: u64,
) -> sqlx::Result<Option<String>> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let old: Option<String> = sqlx::query_scalar(
        "SELECT sha256 FROM episode_videos WHERE run_id = ? AND episode_key = ? AND note IS NULL",
    )
    .bind(row.run)
    .bind(row.key)
    .fetch_optional(&mut *tx)
    .await?;
    sqlx::query(
        "INSERT INTO episode_videos (run_id, episode_key, team_id, sha256, bytes, created_at)
         VALUES (?, ?, ?, ?, ?, ?)
         ON CONFLICT (run_id, episode_key) DO UPDATE SET sha256 = excluded.sha256,
             bytes = excluded.bytes, created_at = excluded.created_at,
             team_id = excluded.team_id, note = NULL",
    )
    .bind(row.run)
    .bind(row.key)
    .bind(row.team)
    .bind(sha256)
    .bind(bytes as i64)
    .bind(row.now)
    .execute(&mut *tx)
    .await?;
    let orphan = match old {
        Some(old) if old != sha256 && !stored(&mut tx, &old).await? => Some(old),
        _ => None,
    };
    tx.commit().await?;
    Ok(orphan)
}

/// Say why `(run, key)` has no video, unless it has a row already (a stored video stays).
pub(crate) async fn note(pool: &SqlitePool, row: Row<'_>, note: &str) -> sqlx::Result<()> {
    sqlx::query(
        "INSERT INTO episode_videos (run_id, episode_key, team_id, sha256, bytes, created_at, note)
         VALUES (?, ?, ?, '', 0, ?, ?) ON CONFLICT (run_id, episode_key) DO NOTHING",
    )
    .bind(row.run)
    .bind(row.key)
    .bind(row.team)
    .bind(row.now)
    .bind(note)
    .execute(pool)
    .await?;
    Ok(())
}

/// The `episode_videos` row an upload writes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Row<'a> {
    pub run: i64,
    pub key: &'a str,
    pub team: i64,
    /// Unix ms.
    pub now: i64,
}

/// Whether a stored row names the file `sha256`, inside a transaction.
async fn stored(tx: &mut sqlx::SqliteConnection, sha256: &str) -> sqlx::Result<bool> {
    let found: Option<i64> =
        sqlx::query_scalar("SELECT 1 FROM episode_videos WHERE sha256 = ? AND note IS NULL LIMIT 1")
            .bind(sha256)
            .fetch_optional(tx)
            .await?;
    Ok(found.is_some())
}

/// The stored file of `(run, key)`: its sha256 and size.
pub(crate) async fn video(pool: &SqlitePool, run: i64, key: &str) -> sqlx::Result<Option<(String, i64)>> {
    sqlx::query_as(
        "SELECT sha256, bytes FROM episode_videos WHERE run_id = ? AND episode_key = ? AND note IS NULL",
    )
    .bind(run)
    .bind(key)
    .fetch_optional(pool)
    .await
}

/// The episode keys of `run` with a row: `None` for a stored video, else the note saying why
/// there is none.
pub(crate) async fn keys(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<(String, Option<String>)>> {
    sqlx::query_as("SELECT episode_key, note FROM episode_videos WHERE run_id = ?")
        .bind(run)
        .fetch_all(pool)
        .await
}

/// Bytes of every stored video (per row, as the budgets count them; traces too: `super::budget`).
#[cfg(test)]
pub(crate) async fn stored_bytes(pool: &SqlitePool) -> sqlx::Result<i64> {
    sqlx::query_scalar("SELECT COALESCE(SUM(bytes), 0) FROM episode_videos WHERE note IS NULL")
        .fetch_one(pool)
        .await
}

/// Delete the links made before `before` (Unix ms); returns the files no link names any more.
pub(crate) async fn expire(pool: &SqlitePool, before: i64) -> sqlx::Result<Vec<String>> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    // Evicted rows go too (their note has no file to explain any more).
    let gone: Vec<Option<String>> = sqlx::query_scalar(
        "DELETE FROM episode_videos WHERE created_at < ? RETURNING CASE WHEN note IS NULL THEN sha256 END",
    )
    .bind(before)
    .fetch_all(&mut *tx)
    .await?;
    let mut orphans = Vec::new();
    for sha in gone.into_iter().flatten() {
        if !orphans.contains(&sha) && !stored(&mut tx, &sha).await? {
            orphans.push(sha);
        }
    }
    tx.commit().await?;
    Ok(orphans)
}

/// Whether a stored row names the file `sha256` (an upload racing the sweep keeps its file).
pub(crate) async fn linked(pool: &SqlitePool, sha256: &str) -> sqlx::Result<bool> {
    let found: Option<i64> =
        sqlx::query_scalar("SELECT 1 FROM episode_videos WHERE sha256 = ? AND note IS NULL LIMIT 1")
            .bind(sha256)
            .fetch_optional(pool)
            .await?;
    Ok(found.is_some())
}
