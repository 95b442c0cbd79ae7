//! Episode traces' rows (`episode_traces`, issue #26): which stored trace file (by sha256) is
//! which (run, episode)'s, and the retention sweep's deletes. The files are
//! `crate::service::videos`'.

use sqlx::sqlite::SqlitePool;

/// Link `(run, key)` to the trace file `sha256`, replacing an earlier link. Returns the file
/// the replaced link named when no row names it any more.
pub(crate) async fn link(
    pool: &SqlitePool,
    run: i64,
    key: &str,
    sha256: &str,
    bytes: u64,
    now: i64,
) -> sqlx::Result<Option<String>> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let old: Option<String> =
        sqlx::query_scalar("SELECT sha256 FROM episode_traces WHERE run_id = ? AND episode_key = ?")
            .bind(run)
            .bind(key)
            .fetch_optional(&mut *tx)
            .await?;
    sqlx::query(
        "INSERT INTO episode_traces (run_id, episode_key, sha256, bytes, created_at) VALUES (?, ?, ?, ?, ?)
         ON CONFLICT (run_id, episode_key) DO UPDATE SET sha256 = excluded.sha256,
             bytes = excluded.bytes, created_at = excluded.created_at",
    )
    .bind(run)
    .bind(key)
    .bind(sha256)
    .bind(bytes as i64)
    .bind(now)
    .execute(&mut *tx)
    .await?;
    let orphan = match old {
        Some(old) if old != sha256 && !named(&mut tx, &old).await? => Some(old),
        _ => None,
    };
    tx.commit().await?;
    Ok(orphan)
}

/// The trace file of `(run, key)`: its sha256.
pub(crate) async fn trace(pool: &SqlitePool, run: i64, key: &str) -> sqlx::Result<Option<String>> {
    sqlx::query_scalar("SELECT sha256 FROM episode_traces WHERE run_id = ? AND episode_key = ?")
        .bind(run)
        .bind(key)
        .fetch_optional(pool)
        .await
}

/// The episode keys of `run` with a trace.
pub(crate) async fn keys(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<String>> {
    sqlx::query_scalar("SELECT episode_key FROM episode_traces WHERE run_id = ?")
        .bind(run)
        .fetch_all(pool)
        .await
}

/// Delete the links made before `before` (Unix ms), and the renders of the same age; returns
/// the files no link names any more.
pub(crate) async fn expire(pool: &SqlitePool, before: i64) -> sqlx::Result<Vec<String>> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let gone: Vec<String> =
        sqlx::query_scalar("DELETE FROM episode_traces WHERE created_at < ? RETURNING sha256")
            .bind(before)
            .fetch_all(&mut *tx)
            .await?;
    sqlx::query("DELETE FROM video_renders WHERE created_at < ? AND state IN ('done', 'failed')")
        .bind(before)
        .execute(&mut *tx)
        .await?;
    let mut orphans = Vec::new();
    for sha in gone {
        if !orphans.contains(&sha) && !named(&mut tx, &sha).await? {
            orphans.push(sha);
        }
    }
    tx.commit().await?;
    Ok(orphans)
}

async fn named(tx: &mut sqlx::SqliteConnection, sha256: &str) -> sqlx::Result<bool> {
    let found: Option<i64> = sqlx::query_scalar("SELECT 1 FROM episode_traces WHERE sha256 = ? LIMIT 1")
        .bind(sha256)
        .fetch_optional(tx)
        .await?;
    Ok(found.is_some())
}

/// Whether a row names the trace file `sha256`.
pub(crate) async fn linked(pool: &SqlitePool, sha256: &str) -> sqlx::Result<bool> {
    named(&mut *pool.acquire().await?, sha256).await
}
