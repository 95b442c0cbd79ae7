//! Verification verdicts on policy runs (`run_verifications`, docs/contest/archive.md) and the
//! reads that `admin verify` and `admin reevaluate` start from: a run's episodes with their stored
//! results, trace files and job specs.

use sqlx::FromRow;
use sqlx::sqlite::SqlitePool;
use sqlx::types::Json;

use crate::episodes::{JobSpec, TaskOutcome};

/// A run as verification sees it: the run that simulated its episodes (itself, or the source
/// of a rescore) and its submission.
#[derive(Debug, Clone, FromRow)]
pub(crate) struct RunHead {
    pub episodes_run: i64,
    pub submission_id: i64,
    pub team: String,
    pub split: String,
    pub kind: String,
    pub sr: Option<f64>,
    pub mse: Option<f64>,
}

pub(crate) async fn run_head(pool: &SqlitePool, run: i64) -> sqlx::Result<Option<RunHead>> {
    sqlx::query_as(
        "SELECT COALESCE(r.source_run_id, r.id) AS episodes_run, s.id AS submission_id,
                t.name AS team, s.split, s.kind, r.sr, r.mse
         FROM scoring_runs r JOIN submissions s ON s.id = r.submission_id
              JOIN teams t ON t.id = s.team_id
         WHERE r.id = ?",
    )
    .bind(run)
    .fetch_optional(pool)
    .await
}

/// One recorded online episode with its trace file, if one is stored.
#[derive(Debug, Clone, FromRow)]
pub(crate) struct StoredEpisode {
    pub episode_key: String,
    pub tasks: Json<Vec<TaskOutcome>>,
    pub failure: Option<String>,
    pub trace_sha256: Option<String>,
    /// Why the trace file is gone (a storage budget), when it is.
    pub trace_note: Option<String>,
    pub spec: Json<JobSpec>,
}

/// The online episodes `run` recorded, in key order.
pub(crate) async fn episodes(pool: &SqlitePool, run: i64) -> sqlx::Result<Vec<StoredEpisode>> {
    sqlx::query_as(
        "SELECT e.episode_key, e.tasks, e.failure, t.sha256 AS trace_sha256, t.note AS trace_note,
                j.spec
         FROM episode_results e JOIN jobs j ON j.id = e.job_id
              LEFT JOIN episode_traces t ON t.run_id = e.run_id AND t.episode_key = e.episode_key
         WHERE e.run_id = ? AND e.mode = 'online'
         ORDER BY e.episode_key",
    )
    .bind(run)
    .fetch_all(pool)
    .await
}

/// A verdict as stored.
#[derive(Debug, Clone, FromRow)]
pub(crate) struct VerdictRow {
    pub run_id: i64,
    pub verdict: String,
    pub episodes: i64,
    pub replayed: i64,
    pub disagreements: String,
    pub binary_version: String,
    pub verified_at: i64,
}

/// Record (or replace) `run`'s verdict.
pub(crate) async fn record(pool: &SqlitePool, v: &VerdictRow) -> sqlx::Result<()> {
    sqlx::query(
        "INSERT INTO run_verifications (run_id, verdict, episodes, replayed, disagreements,
                                        binary_version, verified_at)
         VALUES (?, ?, ?, ?, ?, ?, ?)
         ON CONFLICT (run_id) DO UPDATE SET verdict = excluded.verdict,
             episodes = excluded.episodes, replayed = excluded.replayed,
             disagreements = excluded.disagreements, binary_version = excluded.binary_version,
             verified_at = excluded.verified_at",
    )
    .bind(v.run_id)
    .bind(&v.verdict)
    .bind(v.episodes)
    .bind(v.replayed)
    .bind(&v.disagreements)
    .bind(&v.binary_version)
    .bind(v.verified_at)
    .execute(pool)
    .await?;
    Ok(())
}

/// Every stored verdict, by run.
pub(crate) async fn verdicts(pool: &SqlitePool) -> sqlx::Result<Vec<VerdictRow>> {
    sqlx::query_as("SELECT * FROM run_verifications ORDER BY run_id")
        .fetch_all(pool)
        .await
}
