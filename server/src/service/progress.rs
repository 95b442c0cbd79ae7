//! What a policy run's page shows: progress while it evaluates, then per-episode and per-task
//! results with failure reasons.
//!
//! Policy: the test split's ground truth stays hidden, and a plan's steps and length are part of
//! it. So for test runs each episode shows its success rate, MSE and the distinct failure reasons
//! only (no task list, no log tail, which may quote steps); dev runs show everything.

use serde::Serialize;

use super::AppState;
use crate::episodes::TaskOutcome;
use crate::error::ServiceError;
use crate::store::RunRow;
use crate::store::runs::{self as run_store, ResultRow};

#[derive(Debug, Clone, Serialize)]
pub struct PolicyRunView {
    /// `queued` (no episode started), `running`, `finished` or `platform_failed`.
    pub state: &'static str,
    pub episodes_total: i64,
    /// Episodes with a recorded result (including ones the platform gave up on).
    pub episodes_done: i64,
    /// Episodes being simulated right now.
    pub episodes_running: i64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub finished_at: Option<String>,
    pub episodes: Vec<EpisodeView>,
    /// Episodes not finished yet whose earlier attempt failed on the platform side, and why
    /// (they are retried without counting against the participant).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub retrying: Vec<RetryView>,
}

#[derive(Debug, Clone, Serialize)]
pub struct RetryView {
    pub key: String,
    /// Leases so far.
    pub attempt: i64,
    pub last_error: String,
}

#[derive(Debug, Clone, Serialize)]
pub struct EpisodeView {
    /// `dev-0007` (online) or `dev-0007/offline`.
    pub key: String,
    pub mode: String,
    /// Online: the episode's mean SR_j over the reported tasks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub success_rate: Option<f64>,
    /// Offline: the episode's sample-weighted MSE.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mse: Option<f64>,
    /// Why the episode never ran (the platform gave up after its attempts).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
    /// Distinct task failure reasons, in plan order.
    pub failure_reasons: Vec<String>,
    pub wall_ms: i64,
    pub attempt: i64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tasks: Option<Vec<TaskOutcome>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub log_tail: Option<String>,
}

impl AppState {
    pub(crate) async fn policy_run_view(
        &self,
        run: &RunRow,
        hidden: bool,
    ) -> Result<PolicyRunView, ServiceError> {
        let counts = run_store::job_counts(self.pool(), run.id).await?;
        let results = run_store::results(self.pool(), run.id).await?;
        let state = match run.state.as_str() {
            "finished" => "finished",
            "platform_failed" => "platform_failed",
            _ if counts.started == 0 => "queued",
            _ => "running",
        };
        let episodes = results
            .into_iter()
            .map(|r| episode_view(r, hidden))
            .collect::<Result<Vec<_>, _>>()?;
        let retrying = run_store::retrying(self.pool(), run.id)
            .await?
            .into_iter()
            .map(|(key, attempt, last_error)| RetryView {
                key,
                attempt,
                last_error,
            })
            .collect();
        Ok(PolicyRunView {
            retrying,
            state,
            episodes_total: run.episodes_total,
            episodes_done: episodes.len() as i64,
            episodes_running: counts.leased,
            finished_at: run.finished_at.map(super::rfc3339),
            episodes,
        })
    }
}

fn episode_view(r: ResultRow, hidden: bool) -> Result<EpisodeView, ServiceError> {
    let tasks: Vec<TaskOutcome> = serde_json::from_str(&r.tasks)
        .map_err(|e| anyhow::anyhow!("stored tasks of {}: {e}", r.episode_key))?;
    let online = r.mode == "online";
    let success_rate = (online && !tasks.is_empty())
        .then(|| tasks.iter().filter(|t| t.success).count() as f64 / tasks.len() as f64);
    let samples: u64 = tasks.iter().map(|t| u64::from(t.mse_samples)).sum();
    let mse = (!online && samples > 0).then(|| {
        tasks
            .iter()
            .map(|t| t.mse * f64::from(t.mse_samples))
            .sum::<f64>()
            / samples as f64
    });
    let mut failure_reasons: Vec<String> = Vec::new();
    for t in &tasks {
        if !t.failure_reason.is_empty() && !failure_reasons.contains(&t.failure_reason) {
            failure_reasons.push(t.failure_reason.clone());
        }
    }
    Ok(EpisodeView {
        key: r.episode_key,
        mode: r.mode,
        success_rate,
        mse,
        failure: r.failure,
        failure_reasons,
        wall_ms: r.wall_ms,
        attempt: r.attempt,
        tasks: (!hidden).then_some(tasks),
        log_tail: (!hidden).then_some(r.log_tail),
    })
}
