//! Offline MSE (paper, METRICS): the expert drives, the policy only predicts.
//!
//! The deterministic expert episode is replayed (the oracle, privileged, one action per query,
//! exactly as trajectory collection drives it, through [`run_episode`]). At sampled decision
//! points the rendered observation goes to the participant's policy, which answers with its
//! 16×10 chunk while the expert keeps driving; the chunk is compared with the next 16 actions
//! the expert *executes*. No image is ever stored: each prediction waits in memory only until
//! its 16 expert actions have happened.
//!
//! Definitions (documented in `docs/control-track-worker.md`, the server relies on them):
//! - decision points are the control steps `0, k, 2k, …` of each task, `k` the actions an online
//!   policy executes per chunk (announced in GetSpec); every `sample_every`-th one is sampled;
//! - a sample's MSE is [`chunk_mse`] of the predicted rows against the executed expert rows; the
//!   window stops at the end of its task (a prediction for "pick the bowl" is not judged on the
//!   expert's next sub-task), so the last samples of a task compare the available prefix, at
//!   least one row; values cross as f32, as the wire contract's chunk does; a sample's MSE is
//!   capped at [`FAILED_PREDICTION_MSE`] (reached only by chunks far outside the robot's ranges),
//!   so a task's MSE is always finite and no answer scores worse than a failure;
//! - a failed prediction (timeout, transport error, bad chunk: NaN, wrong shape, gripper out of
//!   range, non-unit quaternion) is a sample worth [`FAILED_PREDICTION_MSE`] and names its reason
//!   in the task's failure reason, so failing never scores better than answering within the
//!   robot's physical ranges; after `max_consecutive_timeouts` successive timeouts or past the
//!   wall budget the policy is not called again and every remaining decision point counts as
//!   failed (the expert still drives, so the sample count does not depend on the policy);
//! - a task's MSE is the mean of its samples (the server weights tasks by `mse_samples`).

use std::time::{Duration, Instant};

use kitchen_r_core::metrics::chunk_mse;
use kitchen_r_sim::Sim;
use serde::{Deserialize, Serialize};

use crate::policy::{
    ACTION_DIM, ChunkTolerance, Corrections, HORIZON, Policy, PolicyError, PolicyInput, PolicySpec,
    PrivilegedScope, check_chunk,
};
use crate::runner::{RunError, RunOptions, StepHook, privileged_observation, run_episode};

/// MSE charged for a failed prediction (defined with the metrics, so server and worker agree).
pub use kitchen_r_core::metrics::FAILED_PREDICTION_MSE;

/// How an offline episode is run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OfflineOptions {
    /// Sim seconds the expert may take per task.
    pub task_time_limit: f64,
    /// Decision points are this many control steps apart (the online `execute`).
    pub execute: usize,
    /// Query the policy at every `sample_every`-th decision point (1 = all of them).
    pub sample_every: usize,
    /// Only the first N plan steps; `None` = all.
    pub max_tasks: Option<usize>,
    /// Pass the expert's privileged state on to the policy (organiser reference runs only).
    pub privileged: bool,
    /// The privileged track: show the policy a privileged observation of this scope of the
    /// expert's world at every sampled decision (as online runs do).
    #[serde(default)]
    pub privileged_observations: Option<PrivilegedScope>,
    /// Stop calling the policy after this many successive timeouts.
    pub max_consecutive_timeouts: u32,
    /// Stop calling the policy once the episode has run this long.
    pub wall_budget: Option<Duration>,
    /// How far a predicted chunk may be off; slips within are corrected and counted.
    #[serde(default)]
    pub chunk_tolerance: ChunkTolerance,
}

impl OfflineOptions {
    /// The offline twin of online options: same limits, every decision point sampled.
    pub fn from_run(run: &RunOptions) -> OfflineOptions {
        OfflineOptions {
            task_time_limit: run.task_time_limit,
            execute: run.execute,
            sample_every: 1,
            max_tasks: run.max_tasks,
            privileged: run.privileged,
            privileged_observations: run.privileged_observations,
            max_consecutive_timeouts: run.max_consecutive_timeouts,
            wall_budget: run.wall_budget,
            chunk_tolerance: run.chunk_tolerance,
        }
    }
}

/// One task of an offline episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OfflineTask {
    pub index: usize,
    pub step: String,
    /// Mean sample MSE; 0 when there are no samples.
    pub mse: f64,
    /// Samples averaged, failed predictions included.
    pub samples: u32,
    /// Predictions that failed (each worth [`FAILED_PREDICTION_MSE`]).
    pub failed: u32,
    /// What went wrong with the policy's predictions; `None` when all were usable.
    pub failure: Option<String>,
    /// Whether the expert completed the task (for logs; the policy is not credited with it).
    pub expert_success: bool,
    pub expert_failure: Option<String>,
    /// Predicted chunk values corrected within tolerance (a warning, not a failure).
    #[serde(default)]
    pub corrections: Corrections,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OfflineOutcome {
    pub episode_id: String,
    pub scene: String,
    pub tasks: Vec<OfflineTask>,
    pub sim_time: f64,
    pub wall_time_s: f64,
    /// Act calls made to the policy.
    pub policy_calls: u32,
}

impl OfflineOutcome {
    /// Mean over all samples of the episode (how the server weights them), if any.
    pub fn mse(&self) -> Option<f64> {
        let n: u32 = self.tasks.iter().map(|t| t.samples).sum();
        let sum: f64 = self.tasks.iter().map(|t| t.mse * f64::from(t.samples)).sum();
        (n > 0).then(|| sum / f64::from(n))
    }
}

/// Replay the episode loaded in `sim` with `expert` driving and `policy` predicting.
///
/// `expert` must be a privileged expert (the oracle); its own failures are recorded per task but
/// never charged to the policy. `hook` sees every executed action (cancellation uses it).
pub fn run_offline(
    sim: &mut Sim,
    expert: &mut dyn Policy,
    policy: &mut dyn Policy,
    opts: &OfflineOptions,
    hook: &mut dyn StepHook,
) -> Result<OfflineOutcome, RunError> {
    let started = Instant::now();
    let expert_opts = RunOptions {
        task_time_limit: opts.task_time_limit,
        execute: 1,
        max_tasks: opts.max_tasks,
        privileged: true,
        privileged_observations: None,
        // The expert is local: it never times out, and the budget limits the policy only.
        max_consecutive_timeouts: u32::MAX,
        wall_budget: None,
        chunk_tolerance: ChunkTolerance::default(),
        budget_abort_at: None,
    };
    // The runner captures the frames the participant's decisions show (its history); the
    // expert's own execution count (one action per query) stays.
    let shown = policy.spec();
    let spec = PolicySpec {
        observation_history: shown.observation_history,
        ..expert.spec().clone()
    };
    let per_chunk = shown.actions_executed_per_chunk.unwrap_or(opts.execute);
    let mut shadow = Shadow {
        spec,
        expert,
        policy,
        opts,
        started,
        period: per_chunk.max(1) * opts.sample_every.max(1),
        step_in_task: 0,
        open: Vec::new(),
        tasks: Vec::new(),
        reset_failure: None,
        timeouts: 0,
        stopped: None,
        calls: 0,
    };
    let expert_run = run_episode(sim, &mut shadow, &expert_opts, None, hook)?;
    shadow.close_all();
    let tasks = expert_run
        .tasks
        .iter()
        .map(|t| {
            let acc = shadow.tasks.get(t.index).cloned().unwrap_or_default();
            OfflineTask {
                index: t.index,
                step: t.step.clone(),
                mse: if acc.samples == 0 {
                    0.0
                } else {
                    acc.sum / f64::from(acc.samples)
                },
                samples: acc.samples,
                failed: acc.failed,
                failure: acc.reason(),
                expert_success: t.success,
                expert_failure: t.failure.clone(),
                corrections: acc.corrections,
            }
        })
        .collect();
    Ok(OfflineOutcome {
        episode_id: expert_run.episode_id,
        scene: expert_run.scene,
        tasks,
        sim_time: expert_run.sim_time,
        wall_time_s: started.elapsed().as_secs_f64(),
        policy_calls: shadow.calls,
    })
}

/// A prediction waiting for the expert's actions.
struct Window {
    predicted: Vec<[f64; ACTION_DIM]>,
    executed: Vec<[f64; ACTION_DIM]>,
}

/// Running totals of one task's samples.
#[derive(Debug, Clone, Default)]
struct TaskAcc {
    samples: u32,
    failed: u32,
    sum: f64,
    first_failure: Option<(u64, String)>,
    corrections: Corrections,
}

impl TaskAcc {
    fn reason(&self) -> Option<String> {
        self.first_failure.as_ref().map(|(step, why)| {
            format!(
                "{} of {} predictions failed; first at step {step}: {why}",
                self.failed, self.samples
            )
        })
    }
}

/// The policy the runner drives: the expert, with the participant's policy listening in.
struct Shadow<'a> {
    spec: PolicySpec,
    expert: &'a mut dyn Policy,
    policy: &'a mut dyn Policy,
    opts: &'a OfflineOptions,
    started: Instant,
    /// Control steps between samples.
    period: usize,
    step_in_task: usize,
    open: Vec<Window>,
    tasks: Vec<TaskAcc>,
    /// The participant's Reset of the current task failed: its predictions all fail with this.
    reset_failure: Option<String>,
    timeouts: u32,
    /// The policy is no longer called (timeouts or wall budget), for this reason.
    stopped: Option<String>,
    calls: u32,
}

impl Shadow<'_> {
    fn task(&mut self) -> &mut TaskAcc {
        if self.tasks.is_empty() {
            self.tasks.push(TaskAcc::default());
        }
        let last = self.tasks.len() - 1;
        &mut self.tasks[last]
    }

    fn fail(&mut self, step: u64, reason: String) {
        let t = self.task();
        t.samples += 1;
        t.failed += 1;
        t.sum += FAILED_PREDICTION_MSE;
        t.first_failure.get_or_insert((step, reason));
    }

    /// Score a window on the expert actions it saw; one with none (the expert itself failed at
    /// that very step) judges nothing and is dropped.
    fn close(&mut self, w: Window) {
        let n = w.executed.len();
        let flat =
            |rows: &[[f64; ACTION_DIM]]| rows.iter().flatten().map(|v| *v as f32).collect::<Vec<f32>>();
        if let Some(mse) = chunk_mse(&flat(&w.predicted[..n]), &flat(&w.executed)) {
            // Capped (and overflow to inf in f32 caught): no answer scores worse than no answer,
            // and a task's mean stays finite whatever a policy sends.
            let mse = if mse.is_finite() {
                mse.min(FAILED_PREDICTION_MSE)
            } else {
                FAILED_PREDICTION_MSE
            };
            let t = self.task();
            t.samples += 1;
            t.sum += mse;
        }
    }

    fn close_all(&mut self) {
        for w in std::mem::take(&mut self.open) {
            self.close(w);
        }
    }

    /// Ask the policy for its chunk at this decision point.
    fn sample(&mut self, input: &PolicyInput<'_>) {
        if self.stopped.is_none() && self.opts.wall_budget.is_some_and(|b| self.started.elapsed() > b) {
            self.stopped = Some("episode aborted: wall-clock budget exceeded".into());
        }
        if let Some(why) = self.stopped.clone().or_else(|| self.reset_failure.clone()) {
            return self.fail(input.step, why);
        }
        let observation = privileged_observation(input.privileged, self.opts.privileged_observations);
        let shown = PolicyInput {
            privileged: if self.opts.privileged {
                input.privileged
            } else {
                None
            },
            privileged_observation: observation.as_ref(),
            ..*input
        };
        self.calls += 1;
        let tolerance = self.opts.chunk_tolerance;
        let answer = self.policy.act(&shown).and_then(|mut c| {
            let fixed = check_chunk(&mut c, HORIZON, &tolerance)?;
            Ok((c, fixed))
        });
        match answer {
            Ok((predicted, fixed)) => {
                self.timeouts = 0;
                self.task().corrections.add(&fixed);
                self.open.push(Window {
                    predicted,
                    executed: Vec::with_capacity(HORIZON),
                });
            }
            Err(e @ PolicyError::Timeout(_)) => {
                self.timeouts += 1;
                if self.timeouts >= self.opts.max_consecutive_timeouts {
                    self.stopped = Some(format!(
                        "episode aborted: {} successive timeouts ({e})",
                        self.timeouts
                    ));
                }
                self.fail(input.step, e.to_string());
            }
            Err(e) => self.fail(input.step, e.to_string()),
        }
    }
}

impl Policy for Shadow<'_> {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }

    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        self.close_all();
        self.tasks.resize_with(task_index + 1, TaskAcc::default);
        self.step_in_task = 0;
        self.reset_failure = None;
        if self.stopped.is_none()
            && let Err(e) = self.policy.reset(episode_id, task_index, sub_task)
        {
            self.reset_failure = Some(format!("reset: {e}"));
        }
        self.expert.reset(episode_id, task_index, sub_task)
    }

    /// Images only for the frames the participant's policy is shown: the step of each sampled
    /// decision point and the `observation_history - 1` steps before it. The frame about to be
    /// captured is step `step_in_task` of the task.
    fn wants_images(&self) -> bool {
        let s = self.step_in_task;
        let next_sample = s.div_ceil(self.period) * self.period;
        self.stopped.is_none() && next_sample - s < self.spec.observation_history.max(1)
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        if self.step_in_task.is_multiple_of(self.period) {
            self.sample(input);
        }
        self.step_in_task += 1;
        let mut chunk = self.expert.act(input)?;
        // Checked here too so that the action recorded below is the one the runner executes.
        check_chunk(&mut chunk, self.spec.horizon, &ChunkTolerance::default())?;
        // The runner executes exactly the first action (execute = 1).
        for w in &mut self.open {
            w.executed.push(chunk[0]);
        }
        let (full, open): (Vec<Window>, Vec<Window>) = std::mem::take(&mut self.open)
            .into_iter()
            .partition(|w| w.executed.len() >= HORIZON);
        self.open = open;
        for w in full {
            self.close(w);
        }
        Ok(chunk)
    }
}
