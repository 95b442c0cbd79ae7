//! How a job ends: a failed attempt is retried or, after `max_attempts`, recorded as a failed
//! episode; the run whose last job closes gets its scores, in the caller's transaction.
//!
//! Integrated runs re-read the linked plan submission's immutable body and recompute EM_j
//! against the ground truth, rather than trusting any stored per-run number.

use std::collections::HashMap;

use sqlx::SqliteConnection;

use crate::episodes;
use crate::error::ServiceError;
use crate::service::AppState;
use crate::service::policies::parse_body;
use crate::states::JobState;
use crate::store::queue::{self, JobRow, NewResult};
use crate::store::runs;

impl AppState {
    /// After a failed attempt: requeue, or record the episode as failed when the job had all its
    /// attempts. Returns whether it was recorded as failed.
    pub(super) async fn retry_or_fail(
        &self,
        conn: &mut SqliteConnection,
        job: &JobRow,
        reason: &str,
        worker: &str,
        now: i64,
    ) -> Result<bool, ServiceError> {
        let attempt_reason = format!("attempt {}: {reason}", job.attempt);
        if job.attempt < job.max_attempts {
            queue::requeue(conn, job.id, &attempt_reason, now).await?;
            tracing::warn!(job = job.id, run = job.run_id, reason = %attempt_reason, "job requeued");
            return Ok(false);
        }
        let failure = format!(
            "the platform gave up after {} attempts; last: {reason}",
            job.attempt
        );
        let result = NewResult {
            job,
            mode: job.spec.mode.as_str(),
            tasks: &[],
            failure: Some(&failure),
            wall_ms: 0,
            log_tail: "",
            worker_id: worker,
            path: None,
        };
        queue::insert_result(conn, &result, now).await?;
        queue::close_job(conn, job.id, JobState::Failed, Some(&attempt_reason), now).await?;
        tracing::warn!(job = job.id, run = job.run_id, %failure, "job failed");
        Ok(true)
    }

    /// When no job of `run` is queued or leased any more, compute and store its scores.
    pub(super) async fn finish_if_done(
        &self,
        conn: &mut SqliteConnection,
        run: i64,
        now: i64,
    ) -> Result<bool, ServiceError> {
        if queue::open_jobs(conn, run).await? > 0 {
            return Ok(false);
        }
        let eps = queue::episodes(conn, run).await?;
        let body = runs::run_submission(conn, run).await?.body;
        let plans = match parse_body(&body)?.plans {
            Some(id) => Some(self.linked_plans(conn, id).await?),
            None => None,
        };
        let scores = episodes::aggregate(&eps, plans.as_ref());
        let platform_failed = !eps.is_empty() && eps.iter().all(|e| e.failure.is_some());
        let done = runs::finish_run(conn, run, &scores, platform_failed, now).await?;
        if done {
            tracing::info!(run, ?scores, platform_failed, "run finished");
        }
        Ok(done)
    }

    /// The linked plan submission's predictions by instruction id, re-read from its immutable
    /// body so EM_j is recomputed against the ground truth rather than trusted from a run.
    pub(crate) async fn linked_plans(
        &self,
        conn: &mut SqliteConnection,
        id: i64,
    ) -> Result<HashMap<String, Vec<String>>, ServiceError> {
        let linked = runs::submission_body_in(conn, id)
            .await?
            .ok_or_else(|| anyhow::anyhow!("linked plans submission {id} is missing"))?;
        let (split, file) = self.stored_plans(&linked.split, &linked.body)?;
        Ok(self
            .content()
            .ground_truth(split)
            .iter()
            .zip(file.plans)
            .filter_map(|(g, p)| p.map(|p| (g.id.clone(), p)))
            .collect())
    }
}
