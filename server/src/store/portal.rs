//! Read queries of the participant pages (`/team`, `/submissions/{id}`).

use sqlx::FromRow;
use sqlx::sqlite::SqlitePool;

use super::ScoreColumns;
use crate::scores::Scores;
use crate::states::{RunState, SubmissionKind};

/// One of a team's submissions with its latest run's scores and state.
#[derive(Debug, Clone, PartialEq, FromRow)]
pub(crate) struct TeamSubmission {
    pub id: i64,
    pub split: String,
    pub kind: SubmissionKind,
    pub created_at: i64,
    #[sqlx(flatten, try_from = "ScoreColumns")]
    pub scores: Scores,
    /// `None` only for a submission whose first run is not stored yet (never, in practice).
    pub state: Option<RunState>,
    pub episodes_total: Option<i64>,
    /// A policy run on the privileged track (its policy received privileged observations).
    pub privileged: bool,
    /// The latest run's grasp mode (plan runs and submissions without a run: the default).
    #[sqlx(try_from = "String")]
    pub grasp_mode: kitchen_r_core::GraspMode,
}

/// A team's latest `limit` submissions, newest first.
pub(crate) async fn team_submissions(
    pool: &SqlitePool,
    team: i64,
    limit: i64,
) -> sqlx::Result<Vec<TeamSubmission>> {
    sqlx::query_as(
        "SELECT s.id, s.split, s.kind, s.created_at, r.em, r.sr, r.mse, r.m, r.p, r.state,
                r.episodes_total,
                -- Plan bodies are not JSON: CASE keeps json_extract to policy bodies.
                CASE WHEN s.kind = 'policy'
                     THEN COALESCE(json_extract(s.body, '$.privileged_observations'), 0)
                     ELSE 0 END AS privileged,
                COALESCE(r.grasp_mode, 'abstract') AS grasp_mode
         FROM submissions s
         LEFT JOIN scoring_runs r
           ON r.id = (SELECT MAX(r2.id) FROM scoring_runs r2 WHERE r2.submission_id = s.id)
         WHERE s.team_id = ? ORDER BY s.id DESC LIMIT ?",
    )
    .bind(team)
    .bind(limit)
    .fetch_all(pool)
    .await
}

/// When the first recorded episode of `run` started (its result's time less its wall time).
pub(crate) async fn run_started_at(pool: &SqlitePool, run: i64) -> sqlx::Result<Option<i64>> {
    sqlx::query_scalar(
        "SELECT MIN(recorded_at - wall_ms) FROM episode_results WHERE run_id = ? AND failure IS NULL",
    )
    .bind(run)
    .fetch_one(pool)
    .await
}
