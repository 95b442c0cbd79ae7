//! A submission as its team (or the organiser) sees it: its latest scoring run, per-instruction
//! results on the dev split only, and why a test plan file is not ranked.

use kitchen_r_core::dataset::Split;
use serde::Serialize;

use super::policies::{self, PolicyInfo};
use super::{AppState, Caller, PolicyRunView, Scores, rfc3339};
use crate::error::ServiceError;
use crate::plans::InstructionScore;
use crate::states::SubmissionKind;
use crate::store;

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct SubmissionView {
    pub id: i64,
    pub team: String,
    pub split: String,
    pub kind: String,
    pub created_at: String,
    pub runs: i64,
    /// Policy submissions: the endpoint as registered (never its token).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub policy: Option<PolicyInfo>,
    /// Whether the submission can appear on the leaderboard.
    pub ranked: bool,
    /// Why it cannot, when it cannot.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unranked_reason: Option<String>,
    pub latest_run: Option<RunView>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct RunView {
    pub id: i64,
    pub scorer_version: String,
    pub created_at: String,
    pub scores: Scores,
    /// Dev plan runs: one row per instruction. Empty on the test split, whose feedback is
    /// aggregate only (`instructions_total`, `instructions_present`).
    pub instructions: Vec<InstructionView>,
    /// Plan runs: instructions in the split and how many the file had a plan for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instructions_total: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instructions_present: Option<usize>,
    /// Policy runs: progress and per-episode, per-task results.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub evaluation: Option<PolicyRunView>,
}

/// Per-instruction result of a dev plan run (test runs show none: per-instruction EM would turn
/// every upload into hundreds of probes of the hidden answers).
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct InstructionView {
    pub id: String,
    pub present: bool,
    pub correct_steps: usize,
    pub total_steps: usize,
    pub em: f64,
}

impl AppState {
    /// Where the robot went in one episode of a submission's latest run, as a PNG over the
    /// scene's top-down map. Dev split only (a test plot would show the hidden plan's goals),
    /// for the submission's own team or the organiser; anything else is not found.
    pub(crate) async fn episode_plot(
        &self,
        caller: &Caller,
        id: i64,
        episode_key: &str,
    ) -> Result<Vec<u8>, ServiceError> {
        let not_found =
            || ServiceError::not_found(format!("a plot of episode {episode_key:?} of submission {id}"));
        let (sub, _) = (self.visible_submission(caller, id).await?)
            .filter(|(s, _)| s.split == Split::Dev.as_str() && s.kind == SubmissionKind::Policy)
            .ok_or_else(not_found)?;
        let run = store::latest_run(self.read_pool(), sub.id)
            .await?
            .ok_or_else(not_found)?;
        let (plot, scene) = store::runs::episode_path(self.read_pool(), run.episodes_run(), episode_key)
            .await?
            .ok_or_else(not_found)?;
        let state = self.clone();
        tokio::task::spawn_blocking(move || state.content().path_png(&scene, &plot))
            .await
            .map_err(anyhow::Error::from)?
            .ok_or_else(not_found)
    }

    /// Submission `id` if `caller` may see it (its own team's, or any for the organiser), with
    /// whether the caller is the organiser: the one ownership rule of every per-submission read.
    pub(crate) async fn visible_submission(
        &self,
        caller: &Caller,
        id: i64,
    ) -> Result<Option<(store::SubmissionRow, bool)>, ServiceError> {
        let viewer = match caller {
            Caller::Organiser(_) => None,
            _ => Some(caller.team()?),
        };
        let sub = store::submission(self.read_pool(), id).await?;
        Ok(sub
            .filter(|s| viewer.as_ref().is_none_or(|t| t.id == s.team_id))
            .map(|s| (s, viewer.is_none())))
    }

    /// A submission with its latest run, for its own team or the organiser.
    pub(crate) async fn get_submission(
        &self,
        caller: &Caller,
        id: i64,
    ) -> Result<SubmissionView, ServiceError> {
        let (sub, _) = (self.visible_submission(caller, id).await?)
            .ok_or_else(|| ServiceError::not_found(format!("submission {id}")))?;
        let hidden = sub.split == Split::Test.as_str();
        let is_policy = sub.kind == SubmissionKind::Policy;
        let latest_run = match store::latest_run(self.read_pool(), id).await? {
            None => None,
            Some(run) => {
                let evaluation = match is_policy {
                    true => Some(self.policy_run_view(&run, hidden, id).await?),
                    false => None,
                };
                let results = match is_policy {
                    true => Vec::new(),
                    false => store::instruction_results(self.read_pool(), run.id).await?,
                };
                let present = results.iter().filter(|i| i.present).count();
                Some(RunView {
                    id: run.id,
                    scorer_version: run.scorer_version,
                    created_at: rfc3339(run.created_at),
                    // Test split: no partial score while a run is in progress (`super::progress`).
                    scores: match hidden && run.state == crate::states::RunState::Active {
                        true => Scores::default(),
                        false => run.scores,
                    },
                    instructions_total: (!is_policy).then_some(results.len()),
                    instructions_present: (!is_policy).then_some(present),
                    instructions: match hidden {
                        true => Vec::new(),
                        false => results.iter().map(instruction_view).collect(),
                    },
                    evaluation,
                })
            }
        };
        let policy = match is_policy {
            true => Some(policies::policy_info(
                &store::submission_body(self.read_pool(), id).await?.body,
            )?),
            false => None,
        };
        let test_plans = sub.kind == SubmissionKind::Plans && sub.split == Split::Test.as_str();
        let unranked_reason = match test_plans {
            true => self.unranked_reason(sub.team_id, sub.id).await?,
            false => None,
        };
        Ok(SubmissionView {
            id: sub.id,
            team: sub.team,
            split: sub.split,
            kind: sub.kind.as_str().to_string(),
            created_at: rfc3339(sub.created_at),
            runs: sub.runs,
            policy,
            ranked: unranked_reason.is_none(),
            unranked_reason,
            latest_run,
        })
    }

    /// Why the test plan submission `id` of `team` cannot appear on the leaderboard (the rule
    /// `store::planning_leaderboard` applies), or `None` when it can.
    pub(super) async fn unranked_reason(&self, team: i64, id: i64) -> Result<Option<String>, ServiceError> {
        Ok(match store::first_test_policy(self.read_pool(), team).await? {
            Some(first) if first < id => Some(format!(
                "created after the team's first test-split policy run (submission {first}), whose \
                 endpoint received the test plans' steps as sub-tasks: scored, not ranked"
            )),
            _ => None,
        })
    }
}

fn instruction_view(i: &InstructionScore) -> InstructionView {
    InstructionView {
        id: i.id.clone(),
        present: i.present,
        correct_steps: i.correct,
        total_steps: i.total,
        em: i.em(),
    }
}
