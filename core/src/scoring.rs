//! Scoring of policy runs, in one place for every side: the server's leaderboard, the simulation
//! workers and a participant's local `kitchen-r eval` all use these types and [`aggregate`], so a
//! local number and the leaderboard's are computed by the same code.
//!
//! Owns: the episode mode and its key, a task's outcome as stored and reported, a recorded
//! episode, a run's scores and how episodes become them (docs/reference/metrics.md). Pure: no I/O, no
//! wire types (conversions to and from the gRPC messages live in `kitchen-r-proto`).
//!
//! Policy decisions:
//! - the tasks of an episode are the ground-truth plan's steps (capped by `max_plan_steps`); a
//!   task the worker did not report (the episode aborted) counts as failed, so stopping early
//!   never helps;
//! - SR = mean over online episodes of mean over tasks of SR_j;
//! - MSE = every offline prediction weighted equally: Σ(mse·samples) / Σ samples; a task the
//!   policy left without any sample (refused or unreachable endpoint) is one failed prediction
//!   ([`FAILED_PREDICTION_MSE`]), so no score improves by failing;
//! - integrated runs (linked plans): EM_j per step against the ground truth, M = mean over
//!   instructions of mean over tasks of (EM_j + SR_j), P = 1/EM + mean over instructions of mean
//!   over tasks of MSE, EM taken over the run's instructions (the same set M averages over).

use std::collections::HashMap;

use serde::{Deserialize, Serialize};

use crate::metrics::{FAILED_PREDICTION_MSE, PlanMatch, em_of, m_score, mean, p_score, step_matches};

/// Suffix of an offline episode's key: `dev-0007/offline`.
pub const OFFLINE_SUFFIX: &str = "/offline";

/// How an episode is run: the policy drives (online, SR) or the expert drives while the policy
/// predicts (offline, MSE).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
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

    /// The episode key of `instruction_id` in this mode: the idempotency key of its result.
    pub fn episode_key(self, instruction_id: &str) -> String {
        match self {
            Mode::Online => instruction_id.to_string(),
            Mode::Offline => format!("{instruction_id}{OFFLINE_SUFFIX}"),
        }
    }
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Mode, String> {
        match s {
            "online" => Ok(Mode::Online),
            "offline" => Ok(Mode::Offline),
            o => Err(format!("mode {o:?}: accepted values are online, offline")),
        }
    }
}

/// Tasks an episode of a `plan_len`-step plan has: all of them, or the first `max_plan_steps`
/// when that is set (0 = no cap).
pub fn task_count(plan_len: usize, max_plan_steps: u32) -> usize {
    match max_plan_steps {
        0 => plan_len,
        n => plan_len.min(n as usize),
    }
}

/// The outcome of one task, as a worker reports it and the server stores it.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct TaskOutcome {
    /// Index of the task in the plan, from 0.
    pub index: u32,
    /// The plan step (`pick the bowl`).
    pub step: String,
    /// SR_j (online episodes; always false offline).
    pub success: bool,
    /// Simulated seconds to success; 0 when not successful.
    pub completion_time_s: f64,
    /// Why the task failed (online) or why predictions failed (offline); empty otherwise.
    pub failure_reason: String,
    /// Offline: mean MSE of the task's samples, and how many there are.
    pub mse: f64,
    pub mse_samples: u32,
}

/// A recorded episode, as scoring sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct Episode {
    pub mode: Mode,
    pub instruction_id: String,
    /// The whole ground-truth plan (EM_j compares against it).
    pub plan: Vec<String>,
    /// Tasks the episode has: the plan's steps, possibly capped (`max_plan_steps`).
    pub task_count: usize,
    pub tasks: Vec<TaskOutcome>,
    /// Set when the episode never ran: the platform gave up after its attempts.
    pub failure: Option<String>,
}

impl Episode {
    /// SR_j for each task; unreported tasks are failures.
    pub fn successes(&self) -> Vec<bool> {
        (0..self.task_count)
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
        (0..self.task_count)
            .filter_map(|j| match self.tasks.iter().find(|t| t.index as usize == j) {
                Some(t) if t.mse_samples > 0 => Some((t.mse, t.mse_samples)),
                Some(t) if t.failure_reason.is_empty() => None,
                _ => Some((FAILED_PREDICTION_MSE, 1)),
            })
            .collect()
    }

    fn task_mses(&self) -> Vec<f64> {
        self.mse_samples().into_iter().map(|(m, _)| m).collect()
    }
}

/// A run's scores; `None` where a score does not apply.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RunScores {
    pub sr: Option<f64>,
    pub mse: Option<f64>,
    /// EM of the linked plans over the run's instructions (integrated runs).
    pub em: Option<f64>,
    pub m: Option<f64>,
    pub p: Option<f64>,
}

/// Offline predictions counted in MSE, failed ones included (see [`Episode::mse_samples`]).
pub fn mse_sample_count(episodes: &[Episode]) -> u64 {
    (episodes.iter().filter(|e| e.mode == Mode::Offline))
        .flat_map(Episode::mse_samples)
        .map(|(_, k)| u64::from(k))
        .sum()
}

/// Scores of a run. `plans` are the linked plan submission's predictions by instruction id
/// (integrated runs only; an instruction missing from the file predicts nothing).
pub fn aggregate(episodes: &[Episode], plans: Option<&HashMap<String, Vec<String>>>) -> RunScores {
    let online: Vec<&Episode> = episodes.iter().filter(|e| e.mode == Mode::Online).collect();
    let offline: Vec<&Episode> = episodes.iter().filter(|e| e.mode == Mode::Offline).collect();
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
                let em = step_matches(predicted(&e.instruction_id), &e.plan);
                em.into_iter().zip(e.successes()).collect()
            })
            .collect();
        scores.m = Some(m_score(&tasks));
    }
    let base = if online.is_empty() { &offline } else { &online };
    let em = em_of(
        &base
            .iter()
            .map(|e| PlanMatch::of(plans.get(&e.instruction_id).map(Vec::as_slice), &e.plan))
            .collect::<Vec<_>>(),
    );
    scores.em = Some(em);
    if !offline.is_empty() {
        let per_instruction: Vec<Vec<f64>> = offline.iter().map(|e| e.task_mses()).collect();
        scores.p = Some(p_score(em, &per_instruction));
    }
    scores
}
