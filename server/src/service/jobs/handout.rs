//! Claimed jobs as handed to a worker: the spec completed for jobs queued by older versions, an
//! opaque episode id per lease, and the endpoint's token opened from its sealed form.
//!
//! Policy: a job whose sealed token cannot be opened (a damaged row; a replaced key is caught
//! at start-up) is never handed out with an empty token: its attempt fails as a platform error
//! naming the reason, so it is retried and, after `max_attempts`, recorded as failed with it.

use kitchen_r_core::dataset::Split;
use kitchen_r_core::plan::place_steps;

use super::LeasedJob;
use crate::error::ServiceError;
use crate::secrets::SecretError;
use crate::service::{AppState, now_ms};
use crate::store::queue;

impl AppState {
    /// `claimed` as handed to `worker`, less the jobs whose token cannot be opened.
    pub(super) async fn hand_out(
        &self,
        claimed: Vec<queue::Claimed>,
        worker: &str,
    ) -> Result<Vec<LeasedJob>, ServiceError> {
        let mut jobs = Vec::with_capacity(claimed.len());
        for c in claimed {
            let id = c.id;
            match self.leased_job(c) {
                Ok(job) => jobs.push(job),
                Err(e) => self.fail_unopened(id, worker, &e).await?,
            }
        }
        Ok(jobs)
    }

    fn leased_job(&self, c: queue::Claimed) -> Result<LeasedJob, SecretError> {
        let mut spec = c.spec;
        if spec.place_targets.len() != place_steps(&spec.plan) {
            // A job queued before specs carried their targets.
            let content = self.content();
            let found = [Split::Dev, Split::Test]
                .into_iter()
                .flat_map(|s| content.ground_truth(s))
                .find(|i| i.id == spec.instruction_id && i.plan == spec.plan);
            if let Some(i) = found {
                spec.place_targets = i.place_targets.clone();
            }
        }
        if let Some(sealed) = spec.endpoint.bearer_token_sealed.take() {
            spec.endpoint.bearer_token = self.open_token(&sealed)?;
        }
        Ok(LeasedJob {
            id: c.id,
            attempt: u32::try_from(c.attempt).unwrap_or(u32::MAX),
            lease_expires_at_ms: c.lease_expires_at,
            run_id: c.run_id,
            episode_key: c.episode_key,
            spec,
            policy_episode_id: opaque_episode_id(),
        })
    }

    /// The lease of job `id` ends as a failed attempt because its token cannot be opened.
    async fn fail_unopened(&self, id: i64, worker: &str, e: &SecretError) -> Result<(), ServiceError> {
        tracing::error!(job = id, error = %e, "the endpoint token cannot be opened: job not handed out");
        let now = now_ms();
        let mut tx = self.pool().begin_with("BEGIN IMMEDIATE").await?;
        let Some(job) = queue::job(&mut tx, id).await? else {
            return Ok(());
        };
        let reason = format!("platform error: {e}");
        self.retry_or_fail(&mut tx, &job, &reason, worker, now).await?;
        let finished = self.finish_if_done(&mut tx, job.run_id, now).await?;
        tx.commit().await?;
        self.after_queue_write(finished);
        Ok(())
    }
}

/// `ep-` and 24 random hex digits.
fn opaque_episode_id() -> String {
    let bytes: [u8; 12] = rand::random();
    format!("ep-{}", hex::encode(bytes))
}
