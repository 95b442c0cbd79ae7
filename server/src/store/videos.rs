//! Episode videos' rows (`episode_videos`): which stored file (by sha256) shows which
//! (run, episode), and the retention sweep's deletes. The files are `crate::videos`'.

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

/// Link `(run, key)` to the file `sha256` (replacing an earlier link).
pub(crate) async fn link(
    pool: &SqlitePool,
    run: i64,
    key: &str,
    sha256: &str,
    bytes: u64,
    now: i64,
) -> sqlx::Result<()> {
    sqlx::query(
        "INSERT INTO episode_videos (run_id, episode_key, sha256, bytes, created_at) VALUES (?, ?, ?, ?, ?)
         ON CONFLICT (run_id, episode_key) DO UPDATE SET sha256 = excluded.sha256,
             bytes = excluded.bytes, created_at = excluded.created_at",
    )
    .bind(run)
    .bind(key)
    .bind(sha256)
    .bind(bytes as i64)
    .bind(now)
    .execute(pool)
    .await?;
    Ok(())
}

/// The file of `(run, key)`: its sha256 and size.
pub(crate) async fn video(pool: &SqlitePool, run: i64, key: &str) -> sqlx::Result<Option<(String, i64)>> {
    sqlx::query_as("SELECT sha256, bytes FROM episode_videos WHERE run_id = ? AND episode_key = ?")
        .bind(run)
        .bind(key)
        .fetch_optional(pool)
        .await
}

/// The episode keys of `run` that have a video.
pub(crate) async fn keys(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<String>> {
    sqlx::query_scalar("SELECT episode_key FROM episode_videos WHERE run_id = ?")
        .bind(run)
        .fetch_all(pool)
        .await
}

/// Delete the links made before `before` (Unix ms); returns the files no link names any more.
pub(crate) async fn expire(pool: &SqlitePool, before: i64) -> sqlx::Result<Vec<String>> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let gone: Vec<String> =
        sqlx::query_scalar("DELETE FROM episode_videos WHERE created_at < ? RETURNING sha256")
            .bind(before)
            .fetch_all(&mut *tx)
            .await?;
    let mut orphans = Vec::new();
    for sha in gone {
        let still: Option<i64> = sqlx::query_scalar("SELECT 1 FROM episode_videos WHERE sha256 = ? LIMIT 1")
            .bind(&sha)
            .fetch_optional(&mut *tx)
            .await?;
        if still.is_none() && !orphans.contains(&sha) {
            orphans.push(sha);
        }
    }
    tx.commit().await?;
    Ok(orphans)
}

/// Whether any link names the file `sha256` (an upload racing the sweep keeps its file).
pub(crate) async fn linked(pool: &SqlitePool, sha256: &str) -> sqlx::Result<bool> {
    let found: Option<i64> = sqlx::query_scalar("SELECT 1 FROM episode_videos WHERE sha256 = ? LIMIT 1")
        .bind(sha256)
        .fetch_optional(pool)
        .await?;
    Ok(found.is_some())
}
