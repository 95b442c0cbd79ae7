//! Episode traces' rows (`episode_traces`; docs/contest/video.md): which stored trace file (by
//! sha256) is which (run, episode)'s, and the retention sweep's deletes. The files are
//! `crate::service::videos`'.
//!
//! A row with a `note` is a trace removed to keep a storage budget (`super::budget`): no file,
//! and its episode says why. Everything that serves, renders or keeps files reads only rows
//! without one. The traces of a test-split run of a ranked submission outlive retention: the
//! organiser verifies a ranked run from them.

use sqlx::sqlite::SqlitePool;

/// Link `(run, key)` to the trace file `sha256`, replacing an earlier link. Returns the file
/// the replaced link named when no row names it any more.
pub(crate) async fn link(
    pool: &SqlitePool,
    row: super::videos::Row<'_>,
    sha256: &str,
    bytes: u64,
) -> sqlx::Result<Option<String>> {
    let (run, key, now) = (row.run, row.key, row.now);
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let old: Option<String> = sqlx::query_scalar(
        "SELECT sha256 FROM episode_traces WHERE run_id = ? AND episode_key = ? AND note IS NULL",
    )
    .bind(run)
    .bind(key)
    .fetch_optional(&mut *tx)
    .await?;
    sqlx::query(
        "INSERT INTO episode_traces (run_id, episode_key, sha256, bytes, created_at, team_id) VALUES (?, ?, ?, ?, ?, ?)
         ON CONFLICT (run_id, episode_key) DO UPDATE SET sha256 = excluded.sha256,
             bytes = excluded.bytes, created_at = excluded.created_at, team_id = excluded.team_id,
             note = NULL",
    )
    .bind(run)
    .bind(key)
    .bind(sha256)
    .bind(bytes as i64)
    .bind(now)
    .bind(row.team)
    .execute(&mut *tx)
    .await?;
    let orphan = match old {
        Some(old) if old != sha256 && !named(&mut tx, &old).await? => Some(old),
        _ => None,
    };
    tx.commit().await?;
    Ok(orphan)
}

/// The stored trace file of `(run, key)`: its sha256.
pub(crate) async fn trace(pool: &SqlitePool, run: i64, key: &str) -> sqlx::Result<Option<String>> {
    sqlx::query_scalar(
        "SELECT sha256 FROM episode_traces WHERE run_id = ? AND episode_key = ? AND note IS NULL",
    )
    .bind(run)
    .bind(key)
    .fetch_optional(pool)
    .await
}

/// The episode keys of `run` with a stored trace.
pub(crate) async fn keys(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<String>> {
    sqlx::query_scalar("SELECT episode_key FROM episode_traces WHERE run_id = ? AND note IS NULL")
        .bind(run)
        .fetch_all(pool)
        .await
}

/// The episodes of `run` whose trace was removed to keep a budget, with the note saying so.
pub(crate) async fn notes(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<(String, String)>> {
    sqlx::query_as("SELECT episode_key, note FROM episode_traces WHERE run_id = ? AND note IS NOT NULL")
        .bind(run)
        .fetch_all(pool)
        .await
}

/// Delete the links made before `before` (Unix ms), but a ranked test run's, and the renders of
/// the same age; returns the files no link names any more.
pub(crate) async fn expire(pool: &SqlitePool, before: i64) -> sqlx::Result<Vec<String>> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let gone: Vec<Option<String>> = sqlx::query_scalar(concat!(
        "DELETE FROM episode_traces AS t WHERE created_at < ? AND NOT ",
        super::budget::protected!(),
        " RETURNING CASE WHEN note IS NULL THEN sha256 END"
    ))
    .bind(before)
    .fetch_all(&mut *tx)
    .await?;
    let gone: Vec<String> = gone.into_iter().flatten().collect();
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
    let found: Option<i64> =
        sqlx::query_scalar("SELECT 1 FROM episode_traces WHERE sha256 = ? AND note IS NULL LIMIT 1")
            .bind(sha256)
            .fetch_optional(tx)
            .await?;
    Ok(found.is_some())
}

/// Whether a stored row names the trace file `sha256`.
pub(crate) async fn linked(pool: &SqlitePool, sha256: &str) -> sqlx::Result<bool> {
    named(&mut *pool.acquire().await?, sha256).await
}
