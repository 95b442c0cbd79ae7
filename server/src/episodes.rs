//! Episodes of a policy run: what a job asks a worker to simulate ([`JobSpec`], stored as JSON in
//! `jobs.spec`), what comes back ([`EpisodeOutcome`]), and how a finished run's episodes become
//! its scores ([`aggregate`]), exactly as DESIGN.md "Metrics" defines them.
//!
//! Pure (no I/O), so the numbers are tested against hand-computed examples.
//!
//! Policy decisions:
//! - the tasks of an episode are the ground-truth plan's steps (capped by `max_plan_steps`); a
//!   task the worker did not report (the episode aborted) counts as failed, so stopping early
//!   never helps;
//! - SR = mean over online episodes of mean over tasks of SR_j;
//! - MSE = every offline prediction weighted equally: Σ(mse·samples) / Σ samples; a task the
//!   policy left without any sample (refused or unreachable endpoint) is one failed prediction,
//!   so no score improves by failing;
//! - integrated runs (a linked plans submission): EM_j per step from the plans' immutable body
//!   against the ground truth, M = mean over instructions of mean over tasks of (EM_j + SR_j),
//!   P = 1/EM + mean over instructions of mean over tasks of MSE, EM taken over the run's
//!   instructions (the same set M averages over), with the same per-task MSEs as above.

use std::collections::HashMap;

use kitchen_r_core::metrics::{
    FAILED_PREDICTION_MSE, PlanMatch, em_of, m_score, mean, p_score, step_matches,
};
use kitchen_r_proto::worker::v1 as pb;
use serde::{Deserialize, Serialize};

/// Suffix of an offline episode's key: `dev-0007/offline`.
pub const OFFLINE_SUFFIX: &str = "/offline";

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    Online,
    Offline,
}

impl Mode {
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Online => "online",
            Mode::Offline => "offline",
        }
    }

    /// The episode key of `instruction_id` in this mode.
    pub fn episode_key(self, instruction_id: &str) -> String {
        match self {
            Mode::Online => instruction_id.to_string(),
            Mode::Offline => format!("{instruction_id}{OFFLINE_SUFFIX}"),
        }
    }
}

/// Where the policy is and the deadlines to call it with (snapshotted at registration).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct EndpointSpec {
    pub url: String,
    /// Empty for none.
    pub bearer_token: String,
    pub call_deadline_ms: u32,
    pub startup_deadline_ms: u32,
    pub episode_budget_ms: u32,
    pub max_successive_timeouts: u32,
}

/// One job: an episode to simulate and the policy to drive it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobSpec {
    pub mode: Mode,
    pub scene_id: String,
    pub instruction_id: String,
    /// The ground-truth plan (always the one executed).
    pub plan: Vec<String>,
    pub seed: u64,
    pub task_time_limit_s: f64,
    pub actions_executed_per_chunk: u32,
    pub teleport_on_failure: bool,
    pub max_plan_steps: u32,
    /// Organiser reference run: the policy gets privileged state.
    pub privileged: bool,
    pub endpoint: EndpointSpec,
    /// World `[x, y, z]` of each `place` step's target, in plan order: the job carries its whole
    /// episode so workers hold no dataset. Empty in specs stored before it was added (filled in
    /// from the content at lease time).
    #[serde(default)]
    pub place_targets: Vec<[f64; 3]>,
}

impl JobSpec {
    /// Tasks the episode has: the plan's steps, capped by `max_plan_steps` (0 = no cap).
    pub fn task_count(&self) -> usize {
        match self.max_plan_steps {
            0 => self.plan.len(),
            n => self.plan.len().min(n as usize),
        }
    }

    /// The episode as a worker gets it; `policy_episode_id` is the opaque name the endpoint sees.
    pub fn episode_proto(&self, policy_episode_id: &str) -> pb::EpisodeSpec {
        pb::EpisodeSpec {
            scene_id: self.scene_id.clone(),
            instruction_id: self.instruction_id.clone(),
            plan: self.plan.clone(),
            seed: self.seed,
            mode: match self.mode {
                Mode::Online => pb::EvalMode::Online,
                Mode::Offline => pb::EvalMode::Offline,
            } as i32,
            task_time_limit_s: self.task_time_limit_s,
            actions_executed_per_chunk: self.actions_executed_per_chunk,
            teleport_on_failure: self.teleport_on_failure,
            max_plan_steps: self.max_plan_steps,
            privileged: self.privileged,
            place_targets: (self.place_targets.iter())
                .map(|t| pb::PlaceTarget {
                    x: t[0],
                    y: t[1],
                    z: t[2],
                })
                .collect(),
            policy_episode_id: policy_episode_id.to_string(),
        }
    }

    pub fn endpoint_proto(&self) -> pb::PolicyEndpoint {
        let e = &self.endpoint;
        pb::PolicyEndpoint {
            url: e.url.clone(),
            bearer_token: e.bearer_token.clone(),
            call_deadline_ms: e.call_deadline_ms,
            startup_deadline_ms: e.startup_deadline_ms,
            episode_budget_ms: e.episode_budget_ms,
            max_successive_timeouts: e.max_successive_timeouts,
        }
    }
}

/// The outcome of one task, as reported (and stored in `episode_results.tasks`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskOutcome {
    pub index: u32,
    pub step: String,
    pub success: bool,
    pub completion_time_s: f64,
    pub failure_reason: String,
    pub mse: f64,
    pub mse_samples: u32,
}

impl From<&pb::TaskResult> for TaskOutcome {
    fn from(t: &pb::TaskResult) -> Self {
        // A non-finite MSE from a worker would poison the run's mean; it is dropped with its samples.
        let finite = t.mse.is_finite() && t.mse >= 0.0;
        TaskOutcome {
            index: t.index,
            step: t.step.clone(),
            success: t.success,
            completion_time_s: if t.completion_time_s.is_finite() {
                t.completion_time_s
            } else {
                0.0
            },
            failure_reason: t.failure_reason.clone(),
            mse: if finite { t.mse } else { 0.0 },
            mse_samples: if finite { t.mse_samples } else { 0 },
        }
    }
}

/// A recorded episode: its spec and what happened.
#[derive(Debug, Clone, PartialEq)]
pub struct Episode {
    pub spec: JobSpec,
    pub tasks: Vec<TaskOutcome>,
    /// Set when the episode never ran: the platform gave up after its attempts.
    pub failure: Option<String>,
}

impl Episode {
    /// SR_j for each task of the plan; unreported tasks are failures.
    pub fn successes(&self) -> Vec<bool> {
        (0..self.spec.task_count())
            .map(|j| self.tasks.iter().any(|t| t.index as usize == j && t.success))
            .collect()
    }

    /// `(MSE, samples)` of each task of an offline episode that counts towards MSE and P. A task
    /// the policy left without a sample (unreported, or reported with a failure and no sample,
    /// e.g. an endpoint that refused the episode) counts as one failed prediction, so dodging the
    /// MSE episodes never improves a score. An episode the platform gave up on counts nothing (it
    /// shows its failure instead), and a task without samples and without a failure (sampling
    /// skipped it) is left out.
    pub fn mse_samples(&self) -> Vec<(f64, u32)> {
        if self.failure.is_some() {
            return Vec::new();
        }
        (0..self.spec.task_count())
            .filter_map(|j| match self.tasks.iter().find(|t| t.index as usize == j) {
                Some(t) if t.mse_samples > 0 => Some((t.mse, t.mse_samples)),
                Some(t) if t.failure_reason.is_empty() => None,
                _ => Some((FAILED_PREDICTION_MSE, 1)),
            })
            .collect()
    }

    /// Per-task MSE of the tasks that count (see [`Episode::mse_samples`]).
    fn task_mses(&self) -> Vec<f64> {
        self.mse_samples().into_iter().map(|(m, _)| m).collect()
    }
}

/// A finished run's scores; `None` where a score does not apply.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RunScores {
    pub sr: Option<f64>,
    pub mse: Option<f64>,
    /// EM of the linked plans over the run's instructions (integrated runs).
    pub em: Option<f64>,
    pub m: Option<f64>,
    pub p: Option<f64>,
}

/// Scores of a finished run. `plans` are the linked plan submission's predictions by instruction
/// id (integrated runs only; an instruction missing from the file predicts nothing).
pub fn aggregate(episodes: &[Episode], plans: Option<&HashMap<String, Vec<String>>>) -> RunScores {
    let online: Vec<&Episode> = episodes.iter().filter(|e| e.spec.mode == Mode::Online).collect();
    let offline: Vec<&Episode> = episodes.iter().filter(|e| e.spec.mode == Mode::Offline).collect();
    let sr = (!online.is_empty()).then(|| {
        mean(
            online
                .iter()
                .map(|e| mean(e.successes().into_iter().map(|s| f64::from(u8::from(s))))),
        )
    });
    let (weighted, samples) = (offline.iter())
        .flat_map(|e| e.mse_samples())
        .fold((0.0, 0u64), |(w, n), (mse, k)| {
            (w + mse * f64::from(k), n + u64::from(k))
        });
    let mse = (samples > 0).then(|| weighted / samples as f64);
    let mut scores = RunScores {
        sr,
        mse,
        ..RunScores::default()
    };
    let Some(plans) = plans else { return scores };
    let predicted = |id: &str| plans.get(id).map(Vec::as_slice).unwrap_or(&[]);
    if !online.is_empty() {
        let tasks: Vec<Vec<(bool, bool)>> = online
            .iter()
            .map(|e| {
                let em = step_matches(predicted(&e.spec.instruction_id), &e.spec.plan);
                em.into_iter().zip(e.successes()).collect()
            })
            .collect();
        scores.m = Some(m_score(&tasks));
    }
    let base = if online.is_empty() { &offline } else { &online };
    let em = em_of(
        &base
            .iter()
            .map(|e| PlanMatch::of(plans.get(&e.spec.instruction_id).map(Vec::as_slice), &e.spec.plan))
            .collect::<Vec<_>>(),
    );
    scores.em = Some(em);
    if !offline.is_empty() {
        let per_instruction: Vec<Vec<f64>> = offline.iter().map(|e| e.task_mses()).collect();
        scores.p = Some(p_score(em, &per_instruction));
    }
    scores
}

#[cfg(test)]
mod tests;
