//! Organiser rescoring: a new scoring run for every submission of every track, appended (never
//! rewriting the old one), against the ground truth loaded now, its scorer version naming the
//! dataset digest.
//!
//! - Plan submissions: EM from the immutable plan file.
//! - Finished policy runs: SR, MSE, and (integrated) M and P against the linked plan file,
//!   recomputed from the episodes already recorded, as a run pointing at the one that simulated
//!   them. When an episode's instruction changed (plan, scene or place targets), the recorded
//!   episodes no longer describe the current task: the run is flagged `needs_resimulation`
//!   instead, since simulating again needs the participant's endpoint and is an organiser's
//!   decision. Runs still evaluating are left alone (they are scored when they finish).

use kitchen_r_core::dataset::Split;
use serde::Serialize;

use super::{AppState, Organiser, now_ms};
use crate::config::PlanLimits;
use crate::episodes;
use crate::error::ServiceError;
use crate::plans;
use crate::service::policies::{CONTROL_SCORER, parse_body};
use crate::states::RunState;
use crate::store::queue;
use crate::store::runs as run_store;
use crate::store::{self, NewRun};

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct RescoreReport {
    /// Plan submissions rescored.
    pub rescored: usize,
    /// Plan submissions whose stored file no longer parses against the dataset.
    pub failed: Vec<RescoreFailure>,
    /// Finished policy runs rescored from their recorded episodes.
    pub policy_runs_rescored: usize,
    /// Policy submissions whose episodes no longer match the ground truth (`error` says which
    /// instruction changed): flagged, scores left as they were.
    pub needs_resimulation: Vec<RescoreFailure>,
    /// Policy submissions left alone (still evaluating, or never scored), with why.
    pub skipped: Vec<RescoreFailure>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct RescoreFailure {
    pub id: i64,
    pub error: String,
}

impl AppState {
    /// Organiser: a new scoring run for every plan submission.
    pub(crate) async fn rescore_all(&self, _: Organiser) -> Result<RescoreReport, ServiceError> {
        let scorer = self.scorer_version();
        let mut report = RescoreReport {
            rescored: 0,
            failed: Vec::new(),
            policy_runs_rescored: 0,
            needs_resimulation: Vec::new(),
            skipped: Vec::new(),
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
        let control_scorer = format!("{CONTROL_SCORER}+{}", self.content().dataset_tag());
        for id in store::policy_submission_ids(self.pool()).await? {
            let note = |error: String| RescoreFailure { id, error };
            match self.rescore_policy(id, &control_scorer).await? {
                PolicyRescore::Rescored => report.policy_runs_rescored += 1,
                PolicyRescore::Stale(why) => report.needs_resimulation.push(note(why)),
                PolicyRescore::Skipped(why) => report.skipped.push(note(why)),
            }
        }
        self.inner.leaderboard.invalidate();
        tracing::info!(
            rescored = report.rescored,
            failed = report.failed.len(),
            policy_runs = report.policy_runs_rescored,
            needs_resimulation = report.needs_resimulation.len(),
            "rescore done"
        );
        Ok(report)
    }

    async fn rescore_one(&self, id: i64, scorer: &str) -> Result<(), ServiceError> {
        let store::SubmissionBody { split, body } = store::submission_body(self.pool(), id).await?;
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

enum PolicyRescore {
    Rescored,
    Stale(String),
    Skipped(String),
}

impl AppState {
    async fn rescore_policy(&self, id: i64, scorer: &str) -> Result<PolicyRescore, ServiceError> {
        let Some(run) = store::latest_run(self.pool(), id).await? else {
            return Ok(PolicyRescore::Skipped("no scoring run".into()));
        };
        if run.state != RunState::Finished {
            return Ok(PolicyRescore::Skipped(format!(
                "run {} is {}",
                run.id,
                run.state.as_str()
            )));
        }
        if run.needs_resimulation {
            return Ok(PolicyRescore::Stale(format!("run {} was flagged before", run.id)));
        }
        let store::SubmissionBody { split, body } = store::submission_body(self.pool(), id).await?;
        let split: Split = split.parse().map_err(|e: String| anyhow::anyhow!(e))?;
        let mut conn = self.pool().acquire().await.map_err(anyhow::Error::from)?;
        let episodes = queue::episodes(&mut conn, run.episodes_run()).await?;
        let truth = self.content().ground_truth(split);
        for e in &episodes {
            let now = truth.iter().find(|i| i.id == e.spec.instruction_id);
            let same = now.is_some_and(|i| {
                i.scene == e.spec.scene_id && i.plan == e.spec.plan && i.place_targets == e.spec.place_targets
            });
            if !same {
                drop(conn);
                run_store::mark_needs_resimulation(self.pool(), run.id).await?;
                return Ok(PolicyRescore::Stale(format!(
                    "instruction {} changed since run {} simulated it",
                    e.spec.instruction_id, run.id
                )));
            }
        }
        let plans = match parse_body(&body)?.plans {
            Some(p) => Some(self.linked_plans(&mut conn, p).await?),
            None => None,
        };
        drop(conn);
        let scores = episodes::aggregate(&episodes, plans.as_ref());
        run_store::insert_derived_run(self.pool(), id, run.episodes_run(), scorer, &scores, now_ms()).await?;
        Ok(PolicyRescore::Rescored)
    }

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
