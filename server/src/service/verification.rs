//! Checking a policy run's result (docs/contest/archive.md), for the organiser only.
//!
//! - `admin verify RUN`: the server hands out the run's recorded episodes (stored results and
//!   trace files); the organiser's `kitchen-r` replays every trace bit for bit, as the workers'
//!   renders do, and reports a verdict, which is stored and shown on the console. The server
//!   never steps physics, so the replay happens where the simulator is.
//! - `admin reevaluate RUN --episodes N`: the server hands out N of the run's jobs as workers
//!   lease them (the endpoint's token opened); the organiser's `kitchen-r` runs them again
//!   against the same endpoint, on the workers' code path, and compares.
//!
//! Both hand out hidden material (test episodes, a team's endpoint token), so both need the
//! organiser token, like the trace and video routes of the test split.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::{AppState, Organiser, now_ms, rfc3339};
use crate::episodes::{JobSpec, TaskOutcome};
use crate::error::ServiceError;
use crate::store::verification::{self as store, RunHead, VerdictRow};

/// `GET /api/v1/admin/runs/{id}/verification`: what a verification replays.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct VerifyPlan {
    pub run: i64,
    /// The run whose episodes were simulated (itself, or the source of a rescore).
    pub episodes_run: i64,
    pub submission: i64,
    pub team: String,
    pub split: String,
    pub episodes: Vec<VerifyEpisode>,
    /// The verdict stored so far, if any.
    pub verdict: Option<Verdict>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct VerifyEpisode {
    pub key: String,
    /// The result the server stored (what the replay must reproduce).
    #[schema(value_type = Vec<Object>)]
    pub tasks: Vec<TaskOutcome>,
    /// The platform gave up on the episode: there is nothing to replay.
    pub failure: Option<String>,
    /// The stored trace file's sha256; `None` when there is none.
    pub trace_sha256: Option<String>,
    /// Why there is no trace file (removed to keep a storage budget), when that is why.
    pub trace_note: Option<String>,
}

/// A verification's result, as `kitchen-r admin verify` reports it.
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub(crate) struct VerdictReport {
    /// Episodes whose replay agreed with their trace and the stored result.
    pub replayed: i64,
    pub disagreements: Vec<Disagreement>,
    /// The `kitchen-r` that replayed them.
    pub binary_version: String,
}

#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub(crate) struct Disagreement {
    pub episode: String,
    pub why: String,
}

/// A stored verdict.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Verdict {
    pub run: i64,
    /// `verified` or `unverified`.
    pub verdict: String,
    pub episodes: i64,
    pub replayed: i64,
    pub disagreements: Vec<Disagreement>,
    pub binary_version: String,
    pub verified_at: String,
}

/// `GET /api/v1/admin/runs/{id}/reevaluation?episodes=N`: the jobs to run again.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Reevaluation {
    pub run: i64,
    pub submission: i64,
    pub team: String,
    pub split: String,
    /// The run's stored SR and MSE (over all its episodes).
    pub stored_sr: Option<f64>,
    pub stored_mse: Option<f64>,
    /// The run's online episodes.
    pub episodes_total: usize,
    /// The first N online episodes in key order, each as its job spec (the endpoint's token
    /// opened) with its stored result.
    pub jobs: Vec<ReevalJob>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct ReevalJob {
    pub key: String,
    #[schema(value_type = Object)]
    pub spec: JobSpec,
    #[schema(value_type = Vec<Object>)]
    pub stored: Vec<TaskOutcome>,
}

impl AppState {
    async fn policy_run(&self, run: i64) -> Result<RunHead, ServiceError> {
        let head = store::run_head(self.pool(), run)
            .await
            .map_err(anyhow::Error::from)?
            .ok_or_else(|| ServiceError::not_found(format!("run {run}")))?;
        if head.kind != "policy" {
            return Err(ServiceError::Conflict(format!(
                "run {run} scores a plan file: it has no episodes to replay"
            )));
        }
        Ok(head)
    }

    pub(crate) async fn verification_plan(&self, _: Organiser, run: i64) -> Result<VerifyPlan, ServiceError> {
        let head = self.policy_run(run).await?;
        let stored = store::episodes(self.pool(), head.episodes_run)
            .await
            .map_err(anyhow::Error::from)?;
        let episodes = (stored.into_iter())
            .map(|e| VerifyEpisode {
                key: e.episode_key,
                tasks: e.tasks.0,
                failure: e.failure,
                trace_sha256: e.trace_sha256.filter(|_| e.trace_note.is_none()),
                trace_note: e.trace_note,
            })
            .collect();
        Ok(VerifyPlan {
            run,
            episodes_run: head.episodes_run,
            submission: head.submission_id,
            team: head.team,
            split: head.split,
            episodes,
            verdict: self.verdict(run).await?,
        })
    }

    /// The stored trace file of one episode of `run`.
    pub(crate) async fn run_trace(&self, _: Organiser, run: i64, key: &str) -> Result<PathBuf, ServiceError> {
        let head = self.policy_run(run).await?;
        let missing = || ServiceError::not_found(format!("a trace of episode {key} of run {run}"));
        let sha = crate::store::traces::trace(self.pool(), head.episodes_run, key)
            .await
            .map_err(anyhow::Error::from)?
            .ok_or_else(missing)?;
        let dir = self.video_dir().ok_or_else(missing)?;
        Ok(super::videos::incoming::trace_path(&dir, &sha))
    }

    /// Store the verdict the organiser's replay reached.
    pub(crate) async fn record_verdict(
        &self,
        _: Organiser,
        run: i64,
        report: VerdictReport,
    ) -> Result<Verdict, ServiceError> {
        let head = self.policy_run(run).await?;
        let episodes = store::episodes(self.pool(), head.episodes_run)
            .await
            .map_err(anyhow::Error::from)?
            .iter()
            .filter(|e| e.failure.is_none())
            .count() as i64;
        let verified = report.disagreements.is_empty() && report.replayed == episodes;
        let row = VerdictRow {
            run_id: run,
            verdict: if verified { "verified" } else { "unverified" }.into(),
            episodes,
            replayed: report.replayed,
            disagreements: serde_json::to_string(&report.disagreements).map_err(anyhow::Error::from)?,
            binary_version: report.binary_version,
            verified_at: now_ms(),
        };
        store::record(self.pool(), &row)
            .await
            .map_err(anyhow::Error::from)?;
        tracing::info!(run, verdict = row.verdict, "run verification recorded");
        Ok(verdict_view(row))
    }

    async fn verdict(&self, run: i64) -> Result<Option<Verdict>, ServiceError> {
        Ok(self.verdicts().await?.into_iter().find(|v| v.run == run))
    }

    /// Every stored verdict (the console's and `admin runs`' column).
    pub(crate) async fn verdicts(&self) -> Result<Vec<Verdict>, ServiceError> {
        let rows = store::verdicts(self.read_pool())
            .await
            .map_err(anyhow::Error::from)?;
        Ok(rows.into_iter().map(verdict_view).collect())
    }

    /// The first `n` online episodes of `run` as jobs to run again.
    pub(crate) async fn reevaluation(
        &self,
        _: Organiser,
        run: i64,
        n: usize,
    ) -> Result<Reevaluation, ServiceError> {
        let head = self.policy_run(run).await?;
        let stored = store::episodes(self.pool(), head.episodes_run)
            .await
            .map_err(anyhow::Error::from)?;
        let episodes_total = stored.len();
        let mut jobs = Vec::new();
        for e in stored.into_iter().filter(|e| e.failure.is_none()).take(n) {
            let mut spec = e.spec.0;
            if let Some(sealed) = spec.endpoint.bearer_token_sealed.take() {
                spec.endpoint.bearer_token = self
                    .open_token(&sealed)
                    .map_err(|err| anyhow::anyhow!("opening the endpoint token of run {run}: {err}"))?;
            }
            jobs.push(ReevalJob {
                key: e.episode_key,
                spec,
                stored: e.tasks.0,
            });
        }
        tracing::info!(run, episodes = jobs.len(), "run handed out for re-evaluation");
        Ok(Reevaluation {
            run,
            submission: head.submission_id,
            team: head.team,
            split: head.split,
            stored_sr: head.sr,
            stored_mse: head.mse,
            episodes_total,
            jobs,
        })
    }
}

fn verdict_view(r: VerdictRow) -> Verdict {
    Verdict {
        run: r.run_id,
        verdict: r.verdict,
        episodes: r.episodes,
        replayed: r.replayed,
        disagreements: serde_json::from_str(&r.disagreements).unwrap_or_default(),
        binary_version: r.binary_version,
        verified_at: rfc3339(r.verified_at),
    }
}
