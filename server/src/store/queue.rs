//! The job queue's SQL: claim, heartbeat, result recording, reaping.
//!
//! Policy: a claim is one `UPDATE … RETURNING` statement, so two workers (or two server tasks)
//! can never lease the same job, and the policy's max concurrency, the per-team cap and the
//! fair order across teams and runs are part of that statement: a run never has more leased jobs
//! than it announced, and a team's backlog cannot starve another team's run. A lease is identified by
//! `(job id, attempt, owner)`; anything quoting an older attempt is stale. Functions taking a
//! `SqliteConnection` run inside the caller's transaction (report and reap must record the
//! result, move the job and finish the run atomically).

use sqlx::sqlite::SqlitePool;
use sqlx::types::Json;
use sqlx::{FromRow, SqliteConnection};

use crate::episodes::{Episode, JobSpec, TaskOutcome};
use crate::states::JobState;

/// A job handed to a worker.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct Claimed {
    pub id: i64,
    pub attempt: i64,
    pub run_id: i64,
    pub episode_key: String,
    #[sqlx(json)]
    pub spec: JobSpec,
    pub lease_expires_at: i64,
}

/// Lease up to `limit` queued jobs to `owner` until `until`, sharing capacity fairly: never
/// taking a run past its `max_concurrency` (0 = unlimited) nor a team past `team_cap` jobs in
/// flight (0 = unlimited), counting the leases they already have, and among the jobs that fit
/// preferring the team with the fewest jobs in flight, then the run with the fewest, then the
/// oldest job. Each job is ranked as if the ones before it were already leased (its team's and
/// its run's load once taken), so a claim of several jobs deals them out round-robin, and a new
/// run's first job goes ahead of a busy team's backlog whatever its size.
pub(crate) async fn claim(
    pool: &SqlitePool,
    owner: &str,
    now: i64,
    until: i64,
    limit: u32,
    team_cap: u32,
) -> sqlx::Result<Vec<Claimed>> {
    let mut jobs: Vec<Claimed> = sqlx::query_as(
        "WITH busy AS (
            SELECT run_id, COUNT(*) AS n FROM jobs WHERE state = 'leased' GROUP BY run_id
         ), team_busy AS (
            SELECT s.team_id, SUM(b.n) AS n FROM busy b
            JOIN scoring_runs r ON r.id = b.run_id JOIN submissions s ON s.id = r.submission_id
            GROUP BY s.team_id
         ), per_run AS (
            SELECT j.id, s.team_id, r.max_concurrency AS cap, COALESCE(b.n, 0) AS busy,
                   ROW_NUMBER() OVER (PARTITION BY j.run_id ORDER BY j.id) AS rn
            FROM jobs j JOIN scoring_runs r ON r.id = j.run_id
            JOIN submissions s ON s.id = r.submission_id
            LEFT JOIN busy b ON b.run_id = j.run_id
            WHERE j.state = 'queued'
         ), per_team AS (
            SELECT p.id, p.busy + p.rn AS run_load, COALESCE(t.n, 0) AS team_busy,
                   ROW_NUMBER() OVER (PARTITION BY p.team_id ORDER BY p.busy + p.rn, p.id) AS tn
            FROM per_run p LEFT JOIN team_busy t ON t.team_id = p.team_id
            WHERE p.cap = 0 OR p.rn + p.busy <= p.cap
         )
         UPDATE jobs SET state = 'leased', lease_owner = ?1, lease_expires_at = ?2,
                         attempt = attempt + 1, updated_at = ?3
         WHERE id IN (SELECT id FROM per_team WHERE ?5 = 0 OR team_busy + tn <= ?5
                      ORDER BY team_busy + tn, run_load, id LIMIT ?4)
         RETURNING id, attempt, run_id, episode_key, spec, lease_expires_at",
    )
    .bind(owner)
    .bind(until)
    .bind(now)
    .bind(i64::from(limit))
    .bind(i64::from(team_cap))
    .fetch_all(pool)
    .await?;
    // RETURNING order is unspecified; hand jobs out oldest first.
    jobs.sort_by_key(|j| j.id);
    Ok(jobs)
}

/// Give back a lease still held by `(job, attempt, owner)`: the job is queued again at once and
/// the lease is not counted as an attempt (`max_attempts` grows by one, so `attempt` still
/// names each lease uniquely and a report from the released lease stays recognisable). `false`
/// when that lease is not held (nothing changes).
pub(crate) async fn release(
    pool: &SqlitePool,
    job: i64,
    attempt: i64,
    owner: &str,
    error: &str,
    now: i64,
) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "UPDATE jobs SET state = 'queued', lease_owner = NULL, lease_expires_at = NULL,
                         max_attempts = max_attempts + 1, last_error = ?1, updated_at = ?2
         WHERE id = ?3 AND attempt = ?4 AND lease_owner = ?5 AND state = 'leased'",
    )
    .bind(error)
    .bind(now)
    .bind(job)
    .bind(attempt)
    .bind(owner)
    .execute(pool)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// Whether any job waits in the queue (a read, cheaper than a claim that finds nothing).
pub(crate) async fn any_queued(pool: &SqlitePool) -> sqlx::Result<bool> {
    sqlx::query_scalar("SELECT EXISTS (SELECT 1 FROM jobs WHERE state = 'queued')")
        .fetch_one(pool)
        .await
}

/// Extend a lease still held by `(job, attempt, owner)`; `None` when it is not (requeued,
/// leased again, finished or cancelled).
pub(crate) async fn heartbeat(
    pool: &SqlitePool,
    job: i64,
    attempt: i64,
    owner: &str,
    until: i64,
    now: i64,
) -> sqlx::Result<Option<i64>> {
    sqlx::query_scalar(
        "UPDATE jobs SET lease_expires_at = ?1, updated_at = ?2
         WHERE id = ?3 AND attempt = ?4 AND lease_owner = ?5 AND state = 'leased'
         RETURNING lease_expires_at",
    )
    .bind(until)
    .bind(now)
    .bind(job)
    .bind(attempt)
    .bind(owner)
    .fetch_optional(pool)
    .await
}

/// A job as the report and reaper paths see it.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct JobRow {
    pub id: i64,
    pub run_id: i64,
    pub episode_key: String,
    #[sqlx(json)]
    pub spec: JobSpec,
    pub state: JobState,
    pub lease_owner: Option<String>,
    pub attempt: i64,
    pub max_attempts: i64,
    pub last_error: Option<String>,
}

/// The columns of a [`JobRow`], as a macro so queries stay `&'static str` literals.
macro_rules! job_columns {
    () => {
        "id, run_id, episode_key, spec, state, lease_owner, attempt, max_attempts, last_error"
    };
}

pub(crate) async fn job(conn: &mut SqliteConnection, id: i64) -> sqlx::Result<Option<JobRow>> {
    sqlx::query_as(concat!("SELECT ", job_columns!(), " FROM jobs WHERE id = ?"))
        .bind(id)
        .fetch_optional(&mut *conn)
        .await
}

/// Leased jobs whose lease ended before `now`.
pub(crate) async fn expired(conn: &mut SqliteConnection, now: i64) -> sqlx::Result<Vec<JobRow>> {
    sqlx::query_as(concat!(
        "SELECT ",
        job_columns!(),
        " FROM jobs WHERE state = 'leased' AND lease_expires_at < ? ORDER BY id"
    ))
    .bind(now)
    .fetch_all(&mut *conn)
    .await
}

pub(crate) async fn result_exists(conn: &mut SqliteConnection, run: i64, key: &str) -> sqlx::Result<bool> {
    let n: i64 =
        sqlx::query_scalar("SELECT COUNT(*) FROM episode_results WHERE run_id = ? AND episode_key = ?")
            .bind(run)
            .bind(key)
            .fetch_one(&mut *conn)
            .await?;
    Ok(n > 0)
}

/// An episode result to record.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NewResult<'a> {
    pub job: &'a JobRow,
    pub mode: &'a str,
    pub tasks: &'a [TaskOutcome],
    pub failure: Option<&'a str>,
    pub wall_ms: i64,
    pub log_tail: &'a str,
    pub worker_id: &'a str,
    /// Where the robot went, for the episode's plot (online episodes of newer workers).
    pub path: Option<&'a kitchen_r_core::topdown::PathPlot>,
}

/// Record a result; `false` when `(run, episode)` was already recorded (nothing changes).
pub(crate) async fn insert_result(
    conn: &mut SqliteConnection,
    r: &NewResult<'_>,
    now: i64,
) -> sqlx::Result<bool> {
    let done = sqlx::query(
        "INSERT INTO episode_results (run_id, episode_key, job_id, mode, tasks, failure, wall_ms, log_tail,
                                      attempt, worker_id, recorded_at, path_z)
         VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT (run_id, episode_key) DO NOTHING",
    )
    .bind(r.job.run_id)
    .bind(&r.job.episode_key)
    .bind(r.job.id)
    .bind(r.mode)
    // Json encodes with serde_json::to_string: the same text as rows written before it.
    .bind(Json(r.tasks))
    .bind(r.failure)
    .bind(r.wall_ms)
    .bind(r.log_tail)
    .bind(r.job.attempt)
    .bind(r.worker_id)
    .bind(now)
    .bind(r.path.map(super::packed::pack_path))
    .execute(&mut *conn)
    .await?;
    Ok(done.rows_affected() == 1)
}

/// Move a job to another state (`done`, `failed`, or back to `queued`), dropping its lease.
pub(crate) async fn close_job(
    conn: &mut SqliteConnection,
    id: i64,
    state: JobState,
    error: Option<&str>,
    now: i64,
) -> sqlx::Result<()> {
    sqlx::query(
        "UPDATE jobs SET state = ?, lease_owner = NULL, lease_expires_at = NULL,
                         last_error = COALESCE(?, last_error), updated_at = ? WHERE id = ?",
    )
    .bind(state)
    .bind(error)
    .bind(now)
    .bind(id)
    .execute(&mut *conn)
    .await?;
    Ok(())
}

/// Put a job back in the queue after a platform failure or an expired lease.
pub(crate) async fn requeue(conn: &mut SqliteConnection, id: i64, error: &str, now: i64) -> sqlx::Result<()> {
    close_job(conn, id, JobState::Queued, Some(error), now).await
}

/// Jobs of a run still queued or leased.
pub(crate) async fn open_jobs(conn: &mut SqliteConnection, run: i64) -> sqlx::Result<i64> {
    sqlx::query_scalar("SELECT COUNT(*) FROM jobs WHERE run_id = ? AND state IN ('queued', 'leased')")
        .bind(run)
        .fetch_one(&mut *conn)
        .await
}

/// Every recorded episode of a run with the spec it ran under, in key order.
pub(crate) async fn episodes(conn: &mut SqliteConnection, run: i64) -> sqlx::Result<Vec<Episode>> {
    let rows: Vec<EpisodeRow> = sqlx::query_as(
        "SELECT j.spec, e.tasks, e.failure FROM episode_results e JOIN jobs j ON j.id = e.job_id
         WHERE e.run_id = ? ORDER BY e.episode_key",
    )
    .bind(run)
    .fetch_all(&mut *conn)
    .await?;
    Ok(rows.into_iter().map(Episode::from).collect())
}

/// A recorded episode joined with its job's spec.
#[derive(FromRow)]
struct EpisodeRow {
    #[sqlx(json)]
    spec: JobSpec,
    #[sqlx(json)]
    tasks: Vec<TaskOutcome>,
    failure: Option<String>,
}

impl From<EpisodeRow> for Episode {
    fn from(r: EpisodeRow) -> Episode {
        let EpisodeRow { spec, tasks, failure } = r;
        Episode { spec, tasks, failure }
    }
}

/// The queue at a glance, for `/metrics`: jobs by state and when the longest-waiting queued job
/// entered the queue (`updated_at` of a queued job: its creation or its last requeue). One
/// statement; the counts read the `(state, id)` index only.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct QueueGauges {
    /// `(state, count)` for every state that has jobs.
    pub by_state: Vec<(String, i64)>,
    pub oldest_queued_at: Option<i64>,
}

pub(crate) async fn gauges(pool: &SqlitePool) -> sqlx::Result<QueueGauges> {
    let rows: Vec<(String, i64, Option<i64>)> = sqlx::query_as(
        "SELECT state, COUNT(*), NULL FROM jobs GROUP BY state
         UNION ALL
         SELECT 'oldest', 0, MIN(updated_at) FROM jobs WHERE state = 'queued'",
    )
    .fetch_all(pool)
    .await?;
    let mut g = QueueGauges::default();
    for (state, n, oldest) in rows {
        match state.as_str() {
            "oldest" => g.oldest_queued_at = oldest,
            _ => g.by_state.push((state, n)),
        }
    }
    Ok(g)
}

/// When each of `ids` was first queued (`created_at`), for the queue-wait histogram.
pub(crate) async fn created_at(pool: &SqlitePool, ids: &[i64]) -> sqlx::Result<Vec<i64>> {
    let ids = serde_json::to_string(ids).unwrap_or_else(|_| "[]".into());
    sqlx::query_scalar("SELECT created_at FROM jobs WHERE id IN (SELECT value FROM json_each(?))")
        .bind(ids)
        .fetch_all(pool)
        .await
}
