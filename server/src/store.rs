//! SQLite persistence: every SQL statement of the server lives here.
//!
//! Policy: submissions are written once and never updated; scores are appended as scoring runs
//! (a rescore is a new run on the same submission). A submission and its first run are inserted
//! in one transaction, so a crash never leaves an unscored submission or an orphan run.
//! Times are Unix milliseconds (UTC) in INTEGER columns.
//!
//! Rows are read by column name into `FromRow` structs, states as [`crate::states`] enums. The
//! JSON columns `jobs.spec` and `episode_results.tasks` are decoded here, once, into typed
//! values (and written with `serde_json`, the text existing databases hold). `submissions.body`
//! stays text: by kind it is a plan file or a policy endpoint's JSON.
//!
//! Submodules: [`runs`] (policy submissions, their runs and results), [`queue`] (the job queue)
//! [`board`] (the maintained leaderboards, refreshed by every write above that changes one) and
//! [`admin`] (the organiser's console: queue, workers, runs, cancel, requeue, backup) and
//! [`portal`] (reads of the participant pages).

pub(crate) mod admin;
pub(crate) mod archive;
pub(crate) mod board;
pub(crate) mod budget;
mod compact;
mod packed;
pub(crate) mod portal;
pub(crate) mod queue;
pub(crate) mod renders;
pub(crate) mod runs;
pub(crate) mod secrets;
pub(crate) mod sessions;
pub(crate) mod traces;
pub(crate) mod verification;
pub(crate) mod videos;

use std::path::Path;
use std::str::FromStr;
use std::time::Duration;

use anyhow::Context;
use kitchen_r_core::dataset::Split;
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteJournalMode, SqlitePool, SqlitePoolOptions, SqliteSynchronous,
};
use sqlx::{FromRow, Sqlite};

use crate::plans::InstructionScore;
use crate::scores::Scores;
use crate::states::{RunState, SubmissionKind};

/// The database's two pools. SQLite in WAL mode has one writer and many readers, so writes get
/// one connection of their own and never queue behind readers for a connection; readers share
/// a read-only pool. Both wait a bounded time for a connection ([`PoolLimits`]); past it the
/// caller gets `sqlx::Error::PoolTimedOut`, which the service answers 503 `busy`.
#[derive(Debug, Clone)]
pub(crate) struct Db {
    /// Every write, and reads that must see the write they belong to.
    pub write: SqlitePool,
    /// Reads that serve pages and boards (leaderboards, submissions, callers).
    pub read: SqlitePool,
}

/// How many readers, and how long a request may wait for a connection (`[db_pool]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PoolLimits {
    pub read_connections: u32,
    pub write_wait: Duration,
    pub read_wait: Duration,
}

impl From<crate::config::DbPool> for PoolLimits {
    fn from(c: crate::config::DbPool) -> Self {
        PoolLimits {
            read_connections: c.read_connections,
            write_wait: Duration::from_millis(c.write_wait_ms),
            read_wait: Duration::from_millis(c.read_wait_ms),
        }
    }
}

impl Default for PoolLimits {
    fn default() -> Self {
        crate::config::DbPool::default().into()
    }
}

/// Open (creating file and directory if missing) and migrate the database, then rebuild the
/// maintained leaderboards.
pub(crate) async fn connect(url: &str, limits: PoolLimits) -> anyhow::Result<Db> {
    let opts = SqliteConnectOptions::from_str(url)
        .with_context(|| format!("bad database URL {url:?}"))?
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        .synchronous(SqliteSynchronous::Normal)
        .busy_timeout(limits.write_wait)
        .foreign_keys(true);
    if let Some(dir) = Path::new(opts.get_filename()).parent()
        && !dir.as_os_str().is_empty()
    {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    let write = SqlitePoolOptions::new()
        .max_connections(1)
        .acquire_timeout(limits.write_wait)
        .connect_with(opts.clone())
        .await
        .with_context(|| format!("cannot open database {url}"))?;
    sqlx::migrate!("../migrations")
        .run(&write)
        .await
        .context("applying migrations")?;
    compact::legacy_rows(&write)
        .await
        .context("compacting plan files and results stored before 20261122250000")?;
    board::rebuild(&write)
        .await
        .context("rebuilding the leaderboards")?;
    if opts.get_filename().as_os_str().is_empty() || url.contains(":memory:") || url.contains("mode=memory") {
        // An in-memory database exists only on its one connection: a second pool would open
        // another, empty one. Reads share the write connection.
        return Ok(Db {
            read: write.clone(),
            write,
        });
    }
    let read = SqlitePoolOptions::new()
        .max_connections(limits.read_connections.max(1))
        .acquire_timeout(limits.read_wait)
        .connect_with(opts.read_only(true).create_if_missing(false))
        .await
        .with_context(|| format!("cannot open database {url} for reading"))?;
    Ok(Db { write, read })
}

#[derive(Debug, Clone, PartialEq, Eq, FromRow)]
pub(crate) struct Team {
    pub id: i64,
    pub name: String,
}

/// The keys under which look-alike team names collide (migration
/// `20261122230000_add_team_name_skeletons.sql` says why there are two).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct NameKeys {
    pub skeleton: String,
    pub skeleton_folded: String,
}

/// Insert a team unless its name is taken or a team shares one of its [`NameKeys`]; `None`
/// then. One statement, so two look-alike names created at the same time cannot both get in.
pub(crate) async fn insert_team(
    pool: &SqlitePool,
    name: &str,
    keys: &NameKeys,
    token_hash: &str,
    now: i64,
) -> sqlx::Result<Option<i64>> {
    // The WHERE clause also settles SQLite's INSERT ... SELECT ... ON CONFLICT ambiguity.
    sqlx::query_scalar(
        "INSERT INTO teams (name, skeleton, skeleton_folded, token_hash, created_at)
         SELECT ?1, ?2, ?3, ?4, ?5
         WHERE NOT EXISTS (SELECT 1 FROM teams WHERE skeleton = ?2 OR skeleton_folded = ?3)
         ON CONFLICT (name) DO NOTHING RETURNING id",
    )
    .bind(name)
    .bind(&keys.skeleton)
    .bind(&keys.skeleton_folded)
    .bind(token_hash)
    .bind(now)
    .fetch_optional(pool)
    .await
}

/// The first team named `name` or sharing one of `keys`: whom a refused name looks like.
pub(crate) async fn team_like(
    pool: &SqlitePool,
    name: &str,
    keys: &NameKeys,
) -> sqlx::Result<Option<String>> {
    sqlx::query_scalar(
        "SELECT name FROM teams WHERE name = ? OR skeleton = ? OR skeleton_folded = ? ORDER BY id LIMIT 1",
    )
    .bind(name)
    .bind(&keys.skeleton)
    .bind(&keys.skeleton_folded)
    .fetch_optional(pool)
    .await
}

/// Give every team without [`NameKeys`] its keys, computed by `keys`: teams made before the
/// columns existed and the baseline team (SQL cannot compute Unicode skeletons). Both keys are
/// always set together; after the first call this finds nothing, through the index.
pub(crate) async fn fill_team_name_keys(pool: &SqlitePool, keys: fn(&str) -> NameKeys) -> sqlx::Result<()> {
    let missing: Vec<(i64, String)> = sqlx::query_as("SELECT id, name FROM teams WHERE skeleton IS NULL")
        .fetch_all(pool)
        .await?;
    for (id, name) in missing {
        let k = keys(&name);
        sqlx::query("UPDATE teams SET skeleton = ?, skeleton_folded = ? WHERE id = ?")
            .bind(&k.skeleton)
            .bind(&k.skeleton_folded)
            .bind(id)
            .execute(pool)
            .await?;
    }
    Ok(())
}

pub(crate) async fn team_by_token_hash(pool: &SqlitePool, token_hash: &str) -> sqlx::Result<Option<Team>> {
    sqlx::query_as("SELECT id, name FROM teams WHERE token_hash = ?")
        .bind(token_hash)
        .fetch_optional(pool)
        .await
}

/// A team's submissions to `split` received at or after `since` (ms). Policy runs the platform
/// could not evaluate (`platform_failed`) do not count: failures caused by the platform never
/// use quota. Nor do runs the organiser cancelled (`cancelled`): cancelling gives the quota back.
pub(crate) async fn count_submissions_since(
    pool: &SqlitePool,
    team: i64,
    split: Split,
    since: i64,
) -> sqlx::Result<i64> {
    sqlx::query_scalar(
        "SELECT COUNT(*) FROM submissions s WHERE s.team_id = ? AND s.split = ? AND s.created_at >= ?
         AND NOT EXISTS (SELECT 1 FROM scoring_runs r WHERE r.submission_id = s.id AND r.state IN ('platform_failed', 'cancelled'))",
    )
        .bind(team)
        .bind(split.as_str())
        .bind(since)
        .fetch_one(pool)
        .await
}

/// The version stored with every scoring run this server makes (`scoring_runs.binary_version`,
/// shown on results cards).
pub(crate) const BINARY_VERSION: &str = env!("CARGO_PKG_VERSION");

/// The scores of one run, as stored.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct NewRun<'a> {
    pub scorer_version: &'a str,
    pub em: f64,
    pub instructions: &'a [InstructionScore],
}

/// Insert an immutable plan submission and its first scoring run in one transaction.
/// Returns `(submission id, run id, created_at)`.
pub(crate) async fn insert_plan_submission(
    pool: &SqlitePool,
    team: i64,
    split: Split,
    body: &str,
    now: i64,
    run: &NewRun<'_>,
) -> sqlx::Result<(i64, i64)> {
    let mut tx = pool.begin().await?;
    let sub: i64 = sqlx::query_scalar(
        "INSERT INTO submissions (team_id, split, kind, body, body_z, created_at)
         VALUES (?, ?, 'plans', '', ?, ?) RETURNING id",
    )
    .bind(team)
    .bind(split.as_str())
    .bind(packed::pack_text(body))
    .bind(now)
    .fetch_one(&mut *tx)
    .await?;
    let run_id = insert_run_in(&mut tx, sub, now, run).await?;
    board::refresh_submission(&mut tx, sub).await?;
    tx.commit().await?;
    Ok((sub, run_id))
}

/// Append a scoring run to an existing submission.
pub(crate) async fn insert_run(
    pool: &SqlitePool,
    submission: i64,
    now: i64,
    run: &NewRun<'_>,
) -> sqlx::Result<i64> {
    let mut tx = pool.begin().await?;
    let id = insert_run_in(&mut tx, submission, now, run).await?;
    board::refresh_submission(&mut tx, submission).await?;
    tx.commit().await?;
    Ok(id)
}

async fn insert_run_in(
    tx: &mut sqlx::Transaction<'_, Sqlite>,
    submission: i64,
    now: i64,
    run: &NewRun<'_>,
) -> sqlx::Result<i64> {
    sqlx::query_scalar(
        "INSERT INTO scoring_runs (submission_id, scorer_version, created_at, em, instructions_z, binary_version)
         VALUES (?, ?, ?, ?, ?, ?) RETURNING id",
    )
    .bind(submission)
    .bind(run.scorer_version)
    .bind(now)
    .bind(run.em)
    .bind(packed::pack_instructions(run.instructions))
    .bind(BINARY_VERSION)
    .fetch_one(&mut **tx)
    .await
}

#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct SubmissionRow {
    pub id: i64,
    pub team_id: i64,
    pub team: String,
    pub split: String,
    pub kind: SubmissionKind,
    pub created_at: i64,
    pub runs: i64,
}

pub(crate) async fn submission(pool: &SqlitePool, id: i64) -> sqlx::Result<Option<SubmissionRow>> {
    sqlx::query_as(
        "SELECT s.id, s.team_id, t.name AS team, s.split, s.kind, s.created_at,
                (SELECT COUNT(*) FROM scoring_runs r WHERE r.submission_id = s.id) AS runs
         FROM submissions s JOIN teams t ON t.id = s.team_id WHERE s.id = ?",
    )
    .bind(id)
    .fetch_optional(pool)
    .await
}

/// The id of a team's first test-split policy submission, if any. Test plan files created after
/// it are not ranked, and integrated test runs must link a plan file created before it: from
/// that run on, the team's endpoint has seen the test ground-truth steps as sub-tasks.
pub(crate) async fn first_test_policy(pool: &SqlitePool, team: i64) -> sqlx::Result<Option<i64>> {
    sqlx::query_scalar(
        "SELECT MIN(id) FROM submissions WHERE team_id = ? AND split = 'test' AND kind = 'policy'",
    )
    .bind(team)
    .fetch_one(pool)
    .await
}

#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct RunRow {
    pub id: i64,
    pub scorer_version: String,
    pub created_at: i64,
    #[sqlx(flatten, try_from = "ScoreColumns")]
    pub scores: Scores,
    pub state: RunState,
    pub episodes_total: i64,
    pub finished_at: Option<i64>,
    /// A rescore of a policy run: the run whose recorded episodes it was computed from.
    pub source_run_id: Option<i64>,
    /// The ground truth changed under this policy run's episodes: only a new simulation can
    /// score it again.
    pub needs_resimulation: bool,
    /// Policy runs: the grasp mode its episodes ran in (plan runs carry the default).
    #[sqlx(try_from = "String")]
    pub grasp_mode: kitchen_r_core::GraspMode,
}

/// The score columns of `scoring_runs`, as [`RunRow`] reads them into its [`Scores`].
#[derive(FromRow)]
struct ScoreColumns {
    em: Option<f64>,
    sr: Option<f64>,
    mse: Option<f64>,
    m: Option<f64>,
    p: Option<f64>,
}

impl From<ScoreColumns> for Scores {
    fn from(c: ScoreColumns) -> Scores {
        let ScoreColumns { em, sr, mse, m, p } = c;
        Scores { em, sr, mse, m, p }
    }
}

impl RunRow {
    /// The run whose episodes (jobs and results) this run's scores come from.
    pub(crate) fn episodes_run(&self) -> i64 {
        self.source_run_id.unwrap_or(self.id)
    }
}

pub(crate) async fn latest_run(pool: &SqlitePool, submission: i64) -> sqlx::Result<Option<RunRow>> {
    sqlx::query_as(
        "SELECT id, scorer_version, created_at, em, sr, mse, m, p, state, episodes_total, finished_at,
                source_run_id, needs_resimulation, grasp_mode
         FROM scoring_runs WHERE submission_id = ? ORDER BY id DESC LIMIT 1",
    )
    .bind(submission)
    .fetch_optional(pool)
    .await
}

/// A plan run's per-instruction results, in instruction order (empty for a policy run).
pub(crate) async fn instruction_results(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<InstructionScore>> {
    let blob: Option<Vec<u8>> = sqlx::query_scalar("SELECT instructions_z FROM scoring_runs WHERE id = ?")
        .bind(run)
        .fetch_optional(pool)
        .await?
        .flatten();
    let mut rows = blob.map_or(Ok(Vec::new()), |z| packed::unpack_instructions(&z))?;
    rows.sort_by(|a, b| a.id.cmp(&b.id));
    Ok(rows)
}

/// Ids of every plan submission, oldest first (for rescoring).
pub(crate) async fn policy_submission_ids(pool: &SqlitePool) -> sqlx::Result<Vec<i64>> {
    sqlx::query_scalar("SELECT id FROM submissions WHERE kind = 'policy' ORDER BY id")
        .fetch_all(pool)
        .await
}

pub(crate) async fn plan_submission_ids(pool: &SqlitePool) -> sqlx::Result<Vec<i64>> {
    sqlx::query_scalar("SELECT id FROM submissions WHERE kind = 'plans' ORDER BY id")
        .fetch_all(pool)
        .await
}

/// What a submission holds: its split and its immutable body (the plan file, or a policy
/// submission's endpoint JSON).
#[derive(Debug, Clone, PartialEq, Eq, FromRow)]
pub(crate) struct SubmissionBody {
    pub split: String,
    pub body: String,
}

/// The split and body of one submission.
pub(crate) async fn submission_body(pool: &SqlitePool, id: i64) -> sqlx::Result<SubmissionBody> {
    let stored: packed::StoredBody =
        sqlx::query_as("SELECT split, body, body_z FROM submissions WHERE id = ?")
            .bind(id)
            .fetch_one(pool)
            .await?;
    stored.into_body()
}

#[cfg(test)]
mod tests;
