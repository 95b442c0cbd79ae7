//! Organiser rescoring: a new scoring run for every plan submission, appended (never
//! rewriting the old one), against the dataset loaded now.
//!
//! Policy runs are not rescored here: their scores come from simulated episodes, and an
//! integrated run's EM_j was recomputed from its linked plans when the run finished.

use kitchen_r_core::dataset::Split;
use serde::Serialize;

use super::{AppState, now_ms};
use crate::config::PlanLimits;
use crate::error::ServiceError;
use crate::plans;
use crate::store::{self, NewRun};

#[derive(Debug, Clone, Serialize)]
pub struct RescoreReport {
    pub rescored: usize,
    pub failed: Vec<RescoreFailure>,
}

#[derive(Debug, Clone, Serialize)]
pub struct RescoreFailure {
    pub id: i64,
    pub error: String,
}

impl AppState {
    /// Organiser: a new scoring run for every plan submission.
    pub async fn rescore_all(&self, admin: Option<&str>) -> Result<RescoreReport, ServiceError> {
        self.require_admin(admin)?;
        let scorer = self.scorer_version();
        let mut report = RescoreReport {
            rescored: 0,
            failed: Vec::new(),
        };
        for id in store::plan_submission_ids(self.pool()).await? {
            match self.rescore_one(id, &scorer).await {
                Ok(()) => report.rescored += 1,
                Err(ServiceError::PlanFile(e)) => report.failed.push(RescoreFailure {
                    id,
                    error: e.to_string(),
                }),
                Err(e) => return Err(e),
            }
        }
        self.inner.leaderboard.invalidate();
        tracing::info!(
            rescored = report.rescored,
            failed = report.failed.len(),
            "rescore done"
        );
        Ok(report)
    }

    async fn rescore_one(&self, id: i64, scorer: &str) -> Result<(), ServiceError> {
        let (split, body) = store::submission_body(self.pool(), id).await?;
        let (split, file) = self.stored_plans(&split, &body)?;
        let score = plans::score(&file, self.content().ground_truth(split));
        let run = NewRun {
            scorer_version: scorer,
            em: score.em,
            instructions: &score.instructions,
        };
        store::insert_run(self.pool(), id, now_ms(), &run).await?;
        Ok(())
    }
}

impl AppState {
    /// Parse a stored plan file again (rescoring, M and P of integrated runs). Stored files were
    /// accepted under the limits of their day; only the ids must still exist.
    pub(crate) fn stored_plans(
        &self,
        split: &str,
        body: &str,
    ) -> Result<(Split, plans::PlanFile), ServiceError> {
        let split: Split = split.parse().map_err(|e: String| anyhow::anyhow!(e))?;
        let file = plans::parse(
            body.as_bytes(),
            split,
            self.content().ground_truth(split).len(),
            &self.content().index,
            &PlanLimits::UNLIMITED,
        )?;
        Ok((split, file))
    }
}
