//! The organiser's console SQL (docs/organiser-console.md): what the queue, the workers and the
//! runs look like now, and the two operations on a run: cancel and requeue.
//!
//! Workers are not registered anywhere: a worker is known by the leases it holds
//! (`jobs.lease_owner`, `jobs.updated_at` moves at every lease and heartbeat) and by the results
//! it recorded (`episode_results.worker_id`, `recorded_at`). Reading these needs no write on the
//! workers' hot path.
//!
//! Cancel and requeue run in one write transaction each, which also refreshes the run's
//! leaderboard entries ([`board::refresh_run`]), like every write that changes a run's state.

use std::path::Path;

use sqlx::sqlite::SqlitePool;
use sqlx::{FromRow, SqliteConnection};

use crate::states::{JobState, RunState};
use crate::store::board;

/// Jobs by state, and when the oldest queued job was created (Unix ms).
#[derive(Debug, Clone, PartialEq, Eq, Default, FromRow)]
pub(crate) struct QueueCounts {
    pub queued: i64,
    pub leased: i64,
    pub done: i64,
    pub failed: i64,
    pub cancelled: i64,
    pub oldest_queued_at: Option<i64>,
}

pub(crate) async fn queue_counts(pool: &SqlitePool) -> sqlx::Result<QueueCounts> {
    sqlx::query_as(
        "SELECT COALESCE(SUM(state = 'queued'), 0) AS queued, COALESCE(SUM(state = 'leased'), 0) AS leased,
                COALESCE(SUM(state = 'done'), 0) AS done, COALESCE(SUM(state = 'failed'), 0) AS failed,
                COALESCE(SUM(state = 'cancelled'), 0) AS cancelled,
                MIN(CASE WHEN state = 'queued' THEN created_at END) AS oldest_queued_at
         FROM jobs",
    )
    .fetch_one(pool)
    .await
}

/// Open jobs per team: episodes in flight (leased) and waiting (queued).
#[derive(Debug, Clone, PartialEq, Eq, FromRow)]
pub(crate) struct TeamLoad {
    pub team: String,
    pub in_flight: i64,
    pub queued: i64,
    /// Runs of the team with an open job.
    pub runs: i64,
}

pub(crate) async fn team_loads(pool: &SqlitePool) -> sqlx::Result<Vec<TeamLoad>> {
    sqlx::query_as(
        "SELECT t.name AS team, SUM(j.state = 'leased') AS in_flight, SUM(j.state = 'queued') AS queued,
                COUNT(DISTINCT j.run_id) AS runs
         FROM jobs j JOIN scoring_runs r ON r.id = j.run_id JOIN submissions s ON s.id = r.submission_id
              JOIN teams t ON t.id = s.team_id
         WHERE j.state IN ('queued', 'leased')
         GROUP BY t.id ORDER BY in_flight DESC, queued DESC, t.name",
    )
    .fetch_all(pool)
    .await
}

/// A job that needs the organiser's eye: stuck (leased past its expiry: the reaper will take
/// it), retrying (an earlier attempt failed) or failed (the platform gave up).
#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct ProblemJob {
    pub id: i64,
    pub run_id: i64,
    pub team: String,
    pub episode_key: String,
    pub state: JobState,
    pub attempt: i64,
    pub max_attempts: i64,
    pub lease_owner: Option<String>,
    pub lease_expires_at: Option<i64>,
    pub last_error: Option<String>,
    pub updated_at: i64,
}

/// At most `limit` problem jobs, most recently changed first.
pub(crate) async fn problem_jobs(pool: &SqlitePool, now: i64, limit: i64) -> sqlx::Result<Vec<ProblemJob>> {
    sqlx::query_as(
        "SELECT j.id, j.run_id, t.name AS team, j.episode_key, j.state, j.attempt, j.max_attempts,
                j.lease_owner, j.lease_expires_at, j.last_error, j.updated_at
         FROM jobs j JOIN scoring_runs r ON r.id = j.run_id JOIN submissions s ON s.id = r.submission_id
              JOIN teams t ON t.id = s.team_id
         WHERE (j.state = 'leased' AND j.lease_expires_at < ?1)
            OR (j.state IN ('queued', 'leased') AND j.last_error IS NOT NULL)
            OR j.state = 'failed'
         ORDER BY j.updated_at DESC, j.id DESC LIMIT ?2",
    )
    .bind(now)
    .bind(limit)
    .fetch_all(pool)
    .await
}

/// A lease held now.
#[derive(Debug, Clone, PartialEq, Eq, FromRow)]
pub(crate) struct HeldLease {
    pub worker: String,
    pub job_id: i64,
    pub run_id: i64,
    pub episode_key: String,
    pub attempt: i64,
    /// The lease's last grant or heartbeat.
    pub updated_at: i64,
    pub lease_expires_at: i64,
}

pub(crate) async fn held_leases(pool: &SqlitePool) -> sqlx::Result<Vec<HeldLease>> {
    sqlx::query_as(
        "SELECT lease_owner AS worker, id AS job_id, run_id, episode_key, attempt, updated_at,
                lease_expires_at
         FROM jobs WHERE state = 'leased' AND lease_owner IS NOT NULL ORDER BY lease_owner, id",
    )
    .fetch_all(pool)
    .await
}

/// Results a worker recorded since a point in time.
#[derive(Debug, Clone, PartialEq, Eq, FromRow)]
pub(crate) struct WorkerReports {
    pub worker: String,
    pub last_report_at: i64,
    pub episodes: i64,
}

pub(crate) async fn worker_reports(pool: &SqlitePool, since: i64) -> sqlx::Result<Vec<WorkerReports>> {
    sqlx::query_as(
        "SELECT worker_id AS worker, MAX(recorded_at) AS last_report_at, COUNT(*) AS episodes
         FROM episode_results WHERE recorded_at >= ? GROUP BY worker_id",
    )
    .bind(since)
    .fetch_all(pool)
    .await
}

/// A policy run with its progress.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct RunProgress {
    pub id: i64,
    pub submission_id: i64,
    pub team: String,
    pub split: String,
    pub state: RunState,
    pub episodes_total: i64,
    /// Episodes with a recorded result (including ones the platform gave up on).
    pub done: i64,
    /// Of which the platform gave up on.
    pub gave_up: i64,
    pub running: i64,
    pub queued: i64,
    pub created_at: i64,
    /// When the first recorded episode started (its result's time less its wall time).
    pub started_at: Option<i64>,
    pub finished_at: Option<i64>,
    pub cancelled_at: Option<i64>,
    pub cancelled_by: Option<String>,
    /// Mean wall time of the episodes that ran.
    pub mean_episode_ms: Option<f64>,
    /// Its policy received privileged observations (the privileged track).
    pub privileged: bool,
}

/// Every active policy run, then the `recent` latest others, newest first. Rescores (runs that
/// simulated nothing) are left out.
pub(crate) async fn runs(pool: &SqlitePool, recent: i64) -> sqlx::Result<Vec<RunProgress>> {
    sqlx::query_as(
        "SELECT r.id, r.submission_id, t.name AS team, s.split, r.state, r.episodes_total,
                (SELECT COUNT(*) FROM episode_results e WHERE e.run_id = r.id) AS done,
                (SELECT COUNT(*) FROM episode_results e WHERE e.run_id = r.id AND e.failure IS NOT NULL) AS gave_up,
                (SELECT COUNT(*) FROM jobs j WHERE j.run_id = r.id AND j.state = 'leased') AS running,
                (SELECT COUNT(*) FROM jobs j WHERE j.run_id = r.id AND j.state = 'queued') AS queued,
                r.created_at,
                (SELECT MIN(e.recorded_at - e.wall_ms) FROM episode_results e
                 WHERE e.run_id = r.id AND e.failure IS NULL) AS started_at,
                r.finished_at, r.cancelled_at, r.cancelled_by,
                (SELECT AVG(e.wall_ms) FROM episode_results e
                 WHERE e.run_id = r.id AND e.failure IS NULL) AS mean_episode_ms,
                -- Only policy rows get here (plan bodies are not JSON); absent = standard.
                COALESCE(json_extract(s.body, '$.privileged_observations'), 0) AS privileged
         FROM scoring_runs r JOIN submissions s ON s.id = r.submission_id JOIN teams t ON t.id = s.team_id
         WHERE s.kind = 'policy' AND r.source_run_id IS NULL
           AND (r.state = 'active' OR r.id IN (
                SELECT r2.id FROM scoring_runs r2 JOIN submissions s2 ON s2.id = r2.submission_id
                WHERE s2.kind = 'policy' AND r2.source_run_id IS NULL AND r2.state <> 'active'
                ORDER BY r2.id DESC LIMIT ?))
         ORDER BY r.state <> 'active', r.id DESC",
    )
    .bind(recent)
    .fetch_all(pool)
    .await
}

/// What cancelling or requeueing found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum RunOp {
    NoSuchRun,
    /// A plan run: scored at upload, it has no episodes.
    NotPolicy,
    /// The run is not in a state the operation applies to.
    WrongState(RunState),
    /// Done: how many jobs changed, and how many of them a worker held.
    Done {
        jobs: u64,
        were_leased: i64,
    },
}

async fn run_state(conn: &mut SqliteConnection, run: i64) -> sqlx::Result<Option<(RunState, String)>> {
    sqlx::query_as(
        "SELECT r.state, s.kind FROM scoring_runs r JOIN submissions s ON s.id = r.submission_id WHERE r.id = ?",
    )
    .bind(run)
    .fetch_optional(&mut *conn)
    .await
}

/// Cancel an active run: its queued and leased jobs become `cancelled` (so they are never
/// leased again, a holder's next heartbeat answers that the lease is gone and its late report is
/// refused as stale), the run becomes `cancelled` with `who` and `now`, and its leaderboard
/// entries are refreshed: all in one transaction.
pub(crate) async fn cancel_run(pool: &SqlitePool, run: i64, who: &str, now: i64) -> sqlx::Result<RunOp> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    match run_state(&mut tx, run).await? {
        None => return Ok(RunOp::NoSuchRun),
        Some((_, kind)) if kind != "policy" => return Ok(RunOp::NotPolicy),
        Some((state, _)) if state != RunState::Active => return Ok(RunOp::WrongState(state)),
        Some(_) => {}
    }
    let were_leased: i64 =
        sqlx::query_scalar("SELECT COUNT(*) FROM jobs WHERE run_id = ? AND state = 'leased'")
            .bind(run)
            .fetch_one(&mut *tx)
            .await?;
    let jobs = sqlx::query(
        "UPDATE jobs SET state = 'cancelled', lease_owner = NULL, lease_expires_at = NULL, updated_at = ?
         WHERE run_id = ? AND state IN ('queued', 'leased')",
    )
    .bind(now)
    .bind(run)
    .execute(&mut *tx)
    .await?
    .rows_affected();
    sqlx::query(
        "UPDATE scoring_runs SET state = 'cancelled', cancelled_at = ?, cancelled_by = ?, finished_at = ?
         WHERE id = ? AND state = 'active'",
    )
    .bind(now)
    .bind(who)
    .bind(now)
    .bind(run)
    .execute(&mut *tx)
    .await?;
    board::refresh_run(&mut tx, run).await?;
    tx.commit().await?;
    Ok(RunOp::Done { jobs, were_leased })
}

/// Requeue a run's failed jobs and its stuck ones (leased past expiry), and give every job it
/// still has to run `attempts` more attempts. The lease counter (`attempt`) keeps counting, so
/// a report quoting an older lease is still recognised as stale; what is reset is the budget.
/// A failed job's give-up result is deleted so the episode can be recorded again; a run that
/// had finished is active again, its scores cleared until its last job closes. Not for a
/// cancelled run. One transaction, with the leaderboard refresh.
pub(crate) async fn requeue_run(pool: &SqlitePool, run: i64, attempts: i64, now: i64) -> sqlx::Result<RunOp> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    match run_state(&mut tx, run).await? {
        None => return Ok(RunOp::NoSuchRun),
        Some((_, kind)) if kind != "policy" => return Ok(RunOp::NotPolicy),
        Some((RunState::Cancelled, _)) => return Ok(RunOp::WrongState(RunState::Cancelled)),
        Some(_) => {}
    }
    let were_leased: i64 = sqlx::query_scalar(
        "SELECT COUNT(*) FROM jobs WHERE run_id = ? AND state = 'leased' AND lease_expires_at < ?",
    )
    .bind(run)
    .bind(now)
    .fetch_one(&mut *tx)
    .await?;
    sqlx::query(
        "DELETE FROM episode_results WHERE run_id = ?1 AND failure IS NOT NULL
         AND episode_key IN (SELECT episode_key FROM jobs WHERE run_id = ?1 AND state = 'failed')",
    )
    .bind(run)
    .execute(&mut *tx)
    .await?;
    let jobs = sqlx::query(
        "UPDATE jobs SET state = 'queued', lease_owner = NULL, lease_expires_at = NULL,
                         last_error = COALESCE(last_error, 'requeued by the organiser'), updated_at = ?1
         WHERE run_id = ?2 AND (state = 'failed' OR (state = 'leased' AND lease_expires_at < ?1))",
    )
    .bind(now)
    .bind(run)
    .execute(&mut *tx)
    .await?
    .rows_affected();
    sqlx::query(
        "UPDATE jobs SET max_attempts = attempt + ? WHERE run_id = ? AND state IN ('queued', 'leased')",
    )
    .bind(attempts)
    .bind(run)
    .execute(&mut *tx)
    .await?;
    if jobs > 0 {
        sqlx::query(
            "UPDATE scoring_runs SET state = 'active', em = NULL, sr = NULL, mse = NULL, m = NULL, p = NULL,
                                     finished_at = NULL
             WHERE id = ? AND state IN ('finished', 'platform_failed')",
        )
        .bind(run)
        .execute(&mut *tx)
        .await?;
    }
    board::refresh_run(&mut tx, run).await?;
    tx.commit().await?;
    Ok(RunOp::Done { jobs, were_leased })
}

/// Write a consistent copy of the whole database to `path` (which must not exist) while it
/// stays in use: `VACUUM INTO` reads one snapshot, as a read transaction, so writers go on.
pub(crate) async fn vacuum_into(pool: &SqlitePool, path: &Path) -> sqlx::Result<()> {
    let path = path
        .to_str()
        .ok_or_else(|| sqlx::Error::Protocol("the backup path is not UTF-8".into()))?;
    sqlx::query("VACUUM INTO ?")
        .bind(path)
        .execute(pool)
        .await
        .map(drop)
}

#[cfg(test)]
mod tests {
    use std::borrow::Cow;

    use super::*;

    /// A database from before `20261122260000_add_run_cancellation` keeps every run, job and
    /// result (and its id sequence) through the table rebuild, foreign keys on afterwards.
    #[tokio::test]
    async fn the_cancellation_migration_keeps_existing_databases_working() {
        let dir = tempfile::tempdir().unwrap();
        let url = format!("sqlite://{}", dir.path().join("old.db").display());
        let opts = <sqlx::sqlite::SqliteConnectOptions as std::str::FromStr>::from_str(&url)
            .unwrap()
            .create_if_missing(true)
            .foreign_keys(true);
        let old = sqlx::sqlite::SqlitePoolOptions::new()
            .max_connections(1)
            .connect_with(opts)
            .await
            .unwrap();
        let mut before = sqlx::migrate!("../migrations");
        before.migrations = Cow::Owned(
            before
                .migrations
                .iter()
                .filter(|m| m.version < 20261122260000)
                .cloned()
                .collect(),
        );
        before.run(&old).await.unwrap();
        for sql in [
            "INSERT INTO teams (name, token_hash, created_at) VALUES ('a', 'h', 1)",
            "INSERT INTO submissions (team_id, split, kind, body, created_at) VALUES (1, 'dev', 'policy', '{}', 1)",
            "INSERT INTO scoring_runs (submission_id, scorer_version, created_at, state, episodes_total)
             VALUES (1, 'v', 1, 'active', 2), (1, 'v', 2, 'finished', 0), (1, 'v', 3, 'finished', 0)",
            "UPDATE scoring_runs SET source_run_id = 1 WHERE id = 2",
            "DELETE FROM scoring_runs WHERE id = 3",
            "INSERT INTO jobs (run_id, episode_key, spec, max_attempts, created_at, updated_at)
             VALUES (1, 'dev-0001', '{}', 3, 1, 1)",
        ] {
            sqlx::query(sql).execute(&old).await.unwrap();
        }
        old.close().await;

        let db = crate::store::connect(&url, Default::default()).await.unwrap();
        let runs: Vec<(i64, String, Option<i64>)> =
            sqlx::query_as("SELECT id, state, source_run_id FROM scoring_runs ORDER BY id")
                .fetch_all(&db.write)
                .await
                .unwrap();
        assert_eq!(
            runs,
            vec![(1, "active".into(), None), (2, "finished".into(), Some(1))]
        );
        let fk: i64 = sqlx::query_scalar("PRAGMA foreign_keys")
            .fetch_one(&db.write)
            .await
            .unwrap();
        assert_eq!(fk, 1);
        let problems: Vec<(String, i64, String, i64)> = sqlx::query_as("PRAGMA foreign_key_check")
            .fetch_all(&db.write)
            .await
            .unwrap();
        assert!(problems.is_empty(), "{problems:?}");
        // Run ids are never reused, and the new state is accepted.
        let next: i64 = sqlx::query_scalar(
            "INSERT INTO scoring_runs (submission_id, scorer_version, created_at) VALUES (1, 'v', 4) RETURNING id",
        )
        .fetch_one(&db.write)
        .await
        .unwrap();
        assert_eq!(next, 4);
        assert_eq!(
            cancel_run(&db.write, 1, "organiser", 5).await.unwrap(),
            RunOp::Done {
                jobs: 1,
                were_leased: 0
            }
        );
        let bad = sqlx::query("UPDATE scoring_runs SET state = 'bogus' WHERE id = 1")
            .execute(&db.write)
            .await;
        assert!(bad.is_err(), "the CHECK constraint still holds");
    }
}
