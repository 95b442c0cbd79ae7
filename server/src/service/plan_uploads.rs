//! Plan uploads: a team's plan file validated, scored against the split's ground truth and
//! stored with its scoring run, within the team's upload rate ([`super::limits`]) and daily
//! quota.

use kitchen_r_core::dataset::Split;
use serde::Serialize;

use super::limits::Refusal;
use super::{AppState, Caller, Scores, now_ms, rfc3339};
use crate::error::ServiceError;
use crate::plans;
use crate::store::{self, NewRun, Team};

const DAY_MS: i64 = 86_400_000;

/// The answer to an accepted plan file.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Submitted {
    pub id: i64,
    #[schema(value_type = crate::schema::SplitName)]
    pub split: Split,
    pub scores: Scores,
    pub warnings: Vec<String>,
}

impl AppState {
    /// Validate, score and store a plan file for `team`.
    pub(crate) async fn submit_plans(
        &self,
        team: &Team,
        split: Split,
        body: &[u8],
    ) -> Result<Submitted, ServiceError> {
        // Before any work: parsing and scoring a large file is what a flood would cost.
        self.check_rate(team, split)?;
        self.store_plans(team, split, body, false).await
    }

    /// The organiser's reference plan file: filed under the reserved `(baseline)` team, exempt
    /// from the rate limit and quota, and marked as a baseline row on the planning board.
    pub(crate) async fn submit_reference_plans(
        &self,
        caller: &Caller,
        split: Split,
        body: &[u8],
    ) -> Result<Submitted, ServiceError> {
        caller.organiser()?;
        let team = store::runs::baseline_team(self.pool(), now_ms()).await?;
        self.store_plans(&team, split, body, true).await
    }

    async fn store_plans(
        &self,
        team: &Team,
        split: Split,
        body: &[u8],
        reference: bool,
    ) -> Result<Submitted, ServiceError> {
        let limit = self.config().max_body_bytes;
        if body.len() > limit {
            let line = plans::line_at(body, limit);
            return Err(plans::PlanFileError::TooLarge { limit, line }.into());
        }
        let gt = self.content().ground_truth(split);
        let file = plans::parse(body, split, gt.len(), &self.content().index, &self.config().plans)?;
        let score = plans::score(&file, gt);
        // Only `id` and `plan` are kept: other fields of a line are dropped before storage.
        let text = file.to_jsonl(gt);
        let scorer = self.scorer_version();
        let run = NewRun {
            scorer_version: &scorer,
            em: score.em,
            instructions: &score.instructions,
        };
        let id = {
            let _guard = self.inner.submit_lock.lock().await;
            let now = now_ms();
            if !reference {
                self.check_quota(team, split, now).await?;
            }
            store::insert_plan_submission(self.pool(), team.id, split, &text, now, &run)
                .await?
                .0
        };
        self.inner.leaderboard.invalidate();
        tracing::info!(submission = id, team = %team.name, %split, em = score.em, "plans submitted");
        let mut warnings = plans::warnings(&score);
        if split == Split::Test
            && !reference
            && let Some(why) = self.unranked_reason(team.id, id).await?
        {
            warnings.push(format!("not ranked: {why}"));
        }
        Ok(Submitted {
            id,
            split,
            scores: Scores::em(Some(score.em)),
            warnings,
        })
    }

    pub(super) async fn check_quota(&self, team: &Team, split: Split, now: i64) -> Result<(), ServiceError> {
        let q = self.config().quota;
        let limit = match split {
            Split::Dev => q.dev_per_day,
            Split::Test => q.test_per_day,
        };
        if limit == 0 {
            return Ok(());
        }
        let day_start = now - now.rem_euclid(DAY_MS);
        let used = store::count_submissions_since(self.pool(), team.id, split, day_start).await?;
        if used < i64::from(limit) {
            return Ok(());
        }
        let reset = day_start + DAY_MS;
        self.count_refusal(Refusal::DailyQuota, split);
        Err(ServiceError::Quota {
            split: split.as_str(),
            limit,
            resets_at: rfc3339(reset),
            retry_after_s: (reset - now + 999) / 1000,
        })
    }
}
