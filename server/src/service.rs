//! The service layer: every rule of the server (authentication, quotas, validation, scoring,
//! leaderboard order) lives here, once. The HTTP and gRPC adapters only translate requests and
//! answers; they call these functions and nothing below them.
//!
//! Submodules: [`policies`] registers policy endpoints and shows their runs; [`jobs`] is the
//! worker-facing queue (lease, heartbeat, report, reaper); [`scores`] is how scores are shown.

pub mod auth;
mod board;
pub mod jobs;
pub mod policies;
mod progress;
mod rescore;

use std::sync::Arc;

use kitchen_r_core::dataset::Split;
use serde::Serialize;
use sqlx::sqlite::SqlitePool;

use crate::config::Config;
use crate::content::Content;
use crate::error::ServiceError;
use crate::leaderboard::LeaderboardCache;
use crate::plans::{self, InstructionScore};
use crate::probe::PolicyProbe;
use crate::states::SubmissionKind;
use crate::store::{self, NewRun, Team};

pub use crate::clock::{now_ms, rfc3339};
pub use crate::scores::{Scores, fmt_score};
pub use auth::{Caller, Organiser, WorkerCred, hash_token, new_token};
pub use policies::{PolicyInfo, RegisterPolicy, Registered};
pub use progress::{EpisodeView, PolicyRunView};
pub use rescore::{RescoreFailure, RescoreReport};

/// Version of the planning scorer; part of every scoring run's `scorer_version`.
pub const PLANNING_SCORER: &str = "planning-em/1";

const DAY_MS: i64 = 86_400_000;

/// Shared state of the server: a cheap `Clone` handle that every adapter holds.
#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    pool: SqlitePool,
    config: Config,
    content: Content,
    admin_hash: String,
    /// Serialises quota check + insert so two concurrent uploads cannot both take the last slot.
    submit_lock: tokio::sync::Mutex<()>,
    leaderboard: LeaderboardCache,
    worker_hash: String,
    probe: Arc<dyn PolicyProbe>,
    /// Woken whenever jobs become available, so long-polling `Lease` calls answer at once.
    jobs_ready: tokio::sync::Notify,
    /// Set at shutdown so long-polling `Lease` calls answer at once instead of holding the
    /// graceful drain for up to 30 s.
    stopping: std::sync::atomic::AtomicBool,
}

impl std::fmt::Debug for AppState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AppState").finish_non_exhaustive()
    }
}

/// A new team and its token (shown once: only its hash is stored).
#[derive(Debug, Clone, Serialize)]
pub struct NewTeam {
    pub id: i64,
    pub name: String,
    pub token: String,
}

/// The answer to an accepted plan file.
#[derive(Debug, Clone, Serialize)]
pub struct Submitted {
    pub id: i64,
    pub split: Split,
    pub scores: Scores,
    pub warnings: Vec<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SubmissionView {
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

#[derive(Debug, Clone, Serialize)]
pub struct RunView {
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
#[derive(Debug, Clone, Serialize)]
pub struct InstructionView {
    pub id: String,
    pub present: bool,
    pub correct_steps: usize,
    pub total_steps: usize,
    pub em: f64,
}

/// The secrets an [`AppState`] checks callers against.
#[derive(Debug, Clone, Copy)]
pub struct Tokens<'a> {
    /// The organiser's token.
    pub admin: &'a str,
    /// The token simulation workers present on the `Worker` gRPC service.
    pub worker: &'a str,
}

impl AppState {
    pub fn new(
        pool: SqlitePool,
        config: Config,
        content: Content,
        tokens: Tokens<'_>,
        probe: Arc<dyn PolicyProbe>,
    ) -> AppState {
        AppState {
            inner: Arc::new(Inner {
                pool,
                config,
                content,
                admin_hash: hash_token(tokens.admin),
                submit_lock: tokio::sync::Mutex::new(()),
                leaderboard: LeaderboardCache::default(),
                worker_hash: hash_token(tokens.worker),
                probe,
                jobs_ready: tokio::sync::Notify::new(),
                stopping: std::sync::atomic::AtomicBool::new(false),
            }),
        }
    }

    pub fn config(&self) -> &Config {
        &self.inner.config
    }

    pub fn content(&self) -> &Content {
        &self.inner.content
    }

    pub fn pool(&self) -> &SqlitePool {
        &self.inner.pool
    }

    pub(crate) fn leaderboard_cache(&self) -> &LeaderboardCache {
        &self.inner.leaderboard
    }

    /// Organiser: make a team and its token.
    pub async fn create_team(&self, _: Organiser, name: &str) -> Result<NewTeam, ServiceError> {
        let name = validate_team_name(name)?;
        let token = new_token();
        let id = store::insert_team(self.pool(), &name, &hash_token(&token), now_ms())
            .await?
            .ok_or_else(|| ServiceError::Conflict(format!("a team named {name:?} already exists")))?;
        tracing::info!(team = id, name = %name, "team created");
        Ok(NewTeam { id, name, token })
    }

    /// Validate, score and store a plan file for `team`.
    pub async fn submit_plans(
        &self,
        team: &Team,
        split: Split,
        body: &[u8],
    ) -> Result<Submitted, ServiceError> {
        let limit = self.config().max_body_bytes;
        if body.len() > limit {
            let line = plans::line_at(body, limit);
            return Err(plans::PlanFileError::TooLarge { limit, line }.into());
        }
        let gt = self.content().ground_truth(split);
        let file = plans::parse(body, split, gt.len(), &self.content().index, &self.config().plans)?;
        let score = plans::score(&file, gt);
        // `parse` accepted it, so it is UTF-8.
        let text = String::from_utf8_lossy(body);
        let scorer = self.scorer_version();
        let run = NewRun {
            scorer_version: &scorer,
            em: score.em,
            instructions: &score.instructions,
        };
        let id = {
            let _guard = self.inner.submit_lock.lock().await;
            let now = now_ms();
            self.check_quota(team, split, now).await?;
            store::insert_plan_submission(self.pool(), team.id, split, &text, now, &run)
                .await?
                .0
        };
        self.inner.leaderboard.invalidate();
        tracing::info!(submission = id, team = %team.name, %split, em = score.em, "plans submitted");
        let mut warnings = plans::warnings(&score);
        if split == Split::Test
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

    async fn check_quota(&self, team: &Team, split: Split, now: i64) -> Result<(), ServiceError> {
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
        Err(ServiceError::Quota {
            split: split.as_str(),
            limit,
            resets_at: rfc3339(reset),
            retry_after_s: (reset - now + 999) / 1000,
        })
    }

    /// A submission with its latest run, for its own team or the organiser.
    pub async fn get_submission(&self, caller: &Caller, id: i64) -> Result<SubmissionView, ServiceError> {
        let viewer = match caller {
            Caller::Organiser(_) => None,
            _ => Some(caller.team()?),
        };
        let sub = store::submission(self.pool(), id)
            .await?
            .filter(|s| viewer.as_ref().is_none_or(|t| t.id == s.team_id))
            .ok_or_else(|| ServiceError::not_found(format!("submission {id}")))?;
        let hidden = sub.split == Split::Test.as_str();
        let is_policy = sub.kind == SubmissionKind::Policy;
        let latest_run = match store::latest_run(self.pool(), id).await? {
            None => None,
            Some(run) => {
                let evaluation = match is_policy {
                    true => Some(self.policy_run_view(&run, hidden).await?),
                    false => None,
                };
                let results = match is_policy {
                    true => Vec::new(),
                    false => store::instruction_results(self.pool(), run.id).await?,
                };
                let present = results.iter().filter(|i| i.present).count();
                Some(RunView {
                    id: run.id,
                    scorer_version: run.scorer_version,
                    created_at: rfc3339(run.created_at),
                    scores: run.scores,
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
                &store::submission_body(self.pool(), id).await?.body,
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
    /// [`store::planning_leaderboard`] applies), or `None` when it can.
    async fn unranked_reason(&self, team: i64, id: i64) -> Result<Option<String>, ServiceError> {
        Ok(match store::first_test_policy(self.pool(), team).await? {
            Some(first) if first < id => Some(format!(
                "created after the team's first test-split policy run (submission {first}), whose \
                 endpoint received the test plans' steps as sub-tasks: scored, not ranked"
            )),
            _ => None,
        })
    }

    fn scorer_version(&self) -> String {
        format!("{PLANNING_SCORER}+{}", self.content().dataset_tag())
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

/// Team names: 1 to 64 characters of letters, digits, space, `-`, `_`, `.`; trimmed.
fn validate_team_name(name: &str) -> Result<String, ServiceError> {
    let name = name.trim();
    let ok_char = |c: char| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_' | '.');
    if name.is_empty() || name.chars().count() > 64 || !name.chars().all(ok_char) {
        return Err(ServiceError::BadRequest(format!(
            "team name {name:?} must be 1 to 64 letters, digits, spaces, '-', '_' or '.'"
        )));
    }
    Ok(name.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn team_names_are_checked() {
        assert_eq!(validate_team_name("  Team Rocket-2 ").unwrap(), "Team Rocket-2");
        for bad in ["", "   ", "a<b>", "x\ny", &"n".repeat(65)] {
            assert!(validate_team_name(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn times_format_as_rfc3339_utc() {
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339(86_400_000 + 1500), "1970-01-02T00:00:01.5Z");
    }
}
