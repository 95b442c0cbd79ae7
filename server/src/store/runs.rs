//! Policy submissions and their scoring runs: inserting a submission with its run and every
//! episode job in one transaction, finishing a run, and reading progress and results back.

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use sqlx::sqlite::SqlitePool;
use sqlx::{FromRow, QueryBuilder, Sqlite, SqliteConnection};

use crate::episodes::{RunScores, TaskOutcome};
use crate::states::RunState;
use crate::store::packed::StoredBody;
use crate::store::{SubmissionBody, Team, board};

/// A policy submission to insert with its run and jobs.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NewPolicyRun<'a> {
    pub team: i64,
    pub split: Split,
    /// The endpoint JSON (`submissions.body`).
    pub body: &'a str,
    pub scorer_version: &'a str,
    pub max_concurrency: u32,
    pub max_attempts: u32,
    /// The grasp mode every job of the run carries (`control.grasp` when it was queued).
    pub grasp: GraspMode,
    /// `(episode_key, spec JSON)` of every job.
    pub jobs: &'a [(String, String)],
}

/// Insert the submission, its active run and its queued jobs atomically: a crash never leaves a
/// run without its episodes. Returns `(submission id, run id)`.
pub(crate) async fn insert_policy_submission(
    pool: &SqlitePool,
    new: &NewPolicyRun<'_>,
    now: i64,
) -> sqlx::Result<(i64, i64)> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let sub: i64 = sqlx::query_scalar(
        "INSERT INTO submissions (team_id, split, kind, body, created_at) VALUES (?, ?, 'policy', ?, ?) RETURNING id",
    )
    .bind(new.team)
    .bind(new.split.as_str())
    .bind(new.body)
    .bind(now)
    .fetch_one(&mut *tx)
    .await?;
    let run = insert_run_with_jobs(&mut tx, sub, new, now).await?;
    board::refresh_submission(&mut tx, sub).await?;
    tx.commit().await?;
    Ok((sub, run))
}

/// A new active run with its queued jobs on an existing policy submission (an organiser's
/// re-simulation request), atomically. `new.team`, `new.split` and `new.body` are not used.
pub(crate) async fn insert_policy_run(
    pool: &SqlitePool,
    submission: i64,
    new: &NewPolicyRun<'_>,
    now: i64,
) -> sqlx::Result<i64> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let run = insert_run_with_jobs(&mut tx, submission, new, now).await?;
    board::refresh_submission(&mut tx, submission).await?;
    tx.commit().await?;
    Ok(run)
}

async fn insert_run_with_jobs(
    tx: &mut sqlx::Transaction<'_, Sqlite>,
    sub: i64,
    new: &NewPolicyRun<'_>,
    now: i64,
) -> sqlx::Result<i64> {
    let run: i64 = sqlx::query_scalar(
        "INSERT INTO scoring_runs (submission_id, scorer_version, created_at, em, state, episodes_total, max_concurrency, grasp_mode, binary_version)
         VALUES (?, ?, ?, NULL, 'active', ?, ?, ?, ?) RETURNING id",
    )
    .bind(sub)
    .bind(new.scorer_version)
    .bind(now)
    .bind(new.jobs.len() as i64)
    .bind(i64::from(new.max_concurrency))
    .bind(new.grasp.as_str())
    .bind(crate::store::BINARY_VERSION)
    .fetch_one(&mut **tx)
    .await?;
    // 6 parameters a row; 100 rows stay far below SQLite's parameter limit.
    for chunk in new.jobs.chunks(100) {
        let mut q = QueryBuilder::<Sqlite>::new(
            "INSERT INTO jobs (run_id, episode_key, spec, max_attempts, created_at, updated_at) ",
        );
        q.push_values(chunk, |mut b, (key, spec)| {
            b.push_bind(run)
                .push_bind(key.clone())
                .push_bind(spec.clone())
                .push_bind(i64::from(new.max_attempts))
                .push_bind(now)
                .push_bind(now);
        });
        q.build().execute(&mut **tx).await?;
    }
    Ok(run)
}

/// Policy runs of a team still evaluating.
pub(crate) async fn active_runs(pool: &SqlitePool, team: i64) -> sqlx::Result<i64> {
    sqlx::query_scalar(
        "SELECT COUNT(*) FROM scoring_runs r JOIN submissions s ON s.id = r.submission_id
         WHERE s.team_id = ? AND r.state = 'active'",
    )
    .bind(team)
    .fetch_one(pool)
    .await
}

/// The split and body of the submission a run belongs to.
pub(crate) async fn run_submission(conn: &mut SqliteConnection, run: i64) -> sqlx::Result<SubmissionBody> {
    let stored: StoredBody = sqlx::query_as(
        "SELECT s.split, s.body, s.body_z FROM scoring_runs r JOIN submissions s ON s.id = r.submission_id
         WHERE r.id = ?",
    )
    .bind(run)
    .fetch_one(&mut *conn)
    .await?;
    stored.into_body()
}

/// The split and body of any submission, inside a transaction.
pub(crate) async fn submission_body_in(
    conn: &mut SqliteConnection,
    id: i64,
) -> sqlx::Result<Option<SubmissionBody>> {
    let stored: Option<StoredBody> =
        sqlx::query_as("SELECT split, body, body_z FROM submissions WHERE id = ?")
            .bind(id)
            .fetch_optional(&mut *conn)
            .await?;
    stored.map(StoredBody::into_body).transpose()
}

/// Store a finished run's scores; only an `active` run is finished (a second call is a no-op).
/// Returns whether the run was finished by this call.
pub(crate) async fn finish_run(
    conn: &mut SqliteConnection,
    run: i64,
    scores: &RunScores,
    platform_failed: bool,
    now: i64,
) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "UPDATE scoring_runs SET state = ?, em = ?, sr = ?, mse = ?, m = ?, p = ?, finished_at = ?
         WHERE id = ? AND state = 'active'",
    )
    .bind(if platform_failed {
        RunState::PlatformFailed
    } else {
        RunState::Finished
    })
    .bind(scores.em)
    .bind(scores.sr)
    .bind(scores.mse)
    .bind(scores.m)
    .bind(scores.p)
    .bind(now)
    .bind(run)
    .execute(&mut *conn)
    .await?;
    let finished = done.rows_affected() == 1;
    if finished {
        board::refresh_run(conn, run).await?;
    }
    Ok(finished)
}

/// A rescore of a finished policy run: a new finished scoring run with `scores` recomputed from
/// the episodes of `source` (which stay keyed by `source`), in the grasp mode they ran in.
pub(crate) async fn insert_derived_run(
    pool: &SqlitePool,
    submission: i64,
    source: i64,
    scorer_version: &str,
    scores: &RunScores,
    now: i64,
) -> sqlx::Result<i64> {
    let mut tx = pool.begin_with("BEGIN IMMEDIATE").await?;
    let id = sqlx::query_scalar(
        "INSERT INTO scoring_runs (submission_id, scorer_version, created_at, em, state,
             episodes_total, max_concurrency, sr, mse, m, p, finished_at, source_run_id, grasp_mode,
             binary_version)
         SELECT ?, ?, ?, ?, 'finished', episodes_total, max_concurrency, ?, ?, ?, ?, ?, ?, grasp_mode, ?
         FROM scoring_runs WHERE id = ? RETURNING id",
    )
    .bind(submission)
    .bind(scorer_version)
    .bind(now)
    .bind(scores.em)
    .bind(scores.sr)
    .bind(scores.mse)
    .bind(scores.m)
    .bind(scores.p)
    .bind(now)
    .bind(source)
    .bind(crate::store::BINARY_VERSION)
    .bind(source)
    .fetch_one(&mut *tx)
    .await?;
    board::refresh_submission(&mut tx, submission).await?;
    tx.commit().await?;
    Ok(id)
}

/// Flag a run whose episodes no longer match the ground truth.
pub(crate) async fn mark_needs_resimulation(pool: &SqlitePool, run: i64) -> sqlx::Result<()> {
    sqlx::query("UPDATE scoring_runs SET needs_resimulation = 1 WHERE id = ?")
        .bind(run)
        .execute(pool)
        .await
        .map(drop)
}

/// Job counts of a run by state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, FromRow)]
pub(crate) struct JobCounts {
    pub queued: i64,
    pub leased: i64,
    pub done: i64,
    pub failed: i64,
    /// Jobs that were leased at least once.
    pub started: i64,
}

pub(crate) async fn job_counts(pool: &SqlitePool, run: i64) -> sqlx::Result<JobCounts> {
    sqlx::query_as(
        "SELECT COALESCE(SUM(state = 'queued'), 0) AS queued, COALESCE(SUM(state = 'leased'), 0) AS leased,
                COALESCE(SUM(state = 'done'), 0) AS done, COALESCE(SUM(state = 'failed'), 0) AS failed,
                COALESCE(SUM(attempt > 0), 0) AS started
         FROM jobs WHERE run_id = ?",
    )
    .bind(run)
    .fetch_one(pool)
    .await
}

/// One recorded episode as the submission page shows it.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct ResultRow {
    pub episode_key: String,
    pub mode: String,
    #[sqlx(json)]
    pub tasks: Vec<TaskOutcome>,
    pub failure: Option<String>,
    pub wall_ms: i64,
    pub log_tail: String,
    pub attempt: i64,
    /// A path was stored with it (the episode has a plot).
    pub has_path: bool,
}

pub(crate) async fn results(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<ResultRow>> {
    sqlx::query_as(
        "SELECT episode_key, mode, tasks, failure, wall_ms, log_tail, attempt,
                path_z IS NOT NULL AS has_path FROM episode_results
         WHERE run_id = ? ORDER BY episode_key",
    )
    .bind(run)
    .fetch_all(pool)
    .await
}

/// An episode's stored path and the scene it ran in; `None` when it has none.
pub(crate) async fn episode_path(
    pool: &SqlitePool,
    run: i64,
    key: &str,
) -> sqlx::Result<Option<(kitchen_r_core::topdown::PathPlot, String)>> {
    let row: Option<(Vec<u8>, sqlx::types::Json<crate::episodes::JobSpec>)> = sqlx::query_as(
        "SELECT r.path_z, j.spec FROM episode_results r JOIN jobs j ON j.id = r.job_id
         WHERE r.run_id = ? AND r.episode_key = ? AND r.path_z IS NOT NULL",
    )
    .bind(run)
    .bind(key)
    .fetch_optional(pool)
    .await?;
    match row {
        None => Ok(None),
        Some((blob, spec)) => Ok(Some((super::packed::unpack_path(&blob)?, spec.0.scene_id))),
    }
}

/// A control or integrated leaderboard row (best entry per team, or a baseline).
/// Name of the reserved team organiser reference runs are filed under. Team names cannot
/// contain parentheses, so no participant can take it.
pub(crate) const BASELINE_TEAM: &str = "(baseline)";

/// The reserved baseline team, created on first use. Its token hash is not a hex digest, so no
/// bearer token ever authenticates as it.
pub(crate) async fn baseline_team(pool: &SqlitePool, now: i64) -> sqlx::Result<Team> {
    sqlx::query_as(
        "INSERT INTO teams (name, token_hash, created_at) VALUES (?, '!baseline: no token', ?)
         ON CONFLICT (name) DO UPDATE SET name = excluded.name RETURNING id, name",
    )
    .bind(BASELINE_TEAM)
    .bind(now)
    .fetch_one(pool)
    .await
}

/// An unfinished job that already failed an attempt.
#[derive(Debug, Clone, PartialEq, Eq, FromRow)]
pub(crate) struct RetryingJob {
    pub episode_key: String,
    /// Leases so far.
    pub attempt: i64,
    pub last_error: String,
}

/// Unfinished jobs of a run that already failed an attempt, in key order.
pub(crate) async fn retrying(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<RetryingJob>> {
    sqlx::query_as(
        "SELECT episode_key, attempt, last_error FROM jobs
         WHERE run_id = ? AND state IN ('queued', 'leased') AND last_error IS NOT NULL ORDER BY episode_key",
    )
    .bind(run)
    .fetch_all(pool)
    .await
}
