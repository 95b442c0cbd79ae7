//! Online evaluation of one episode (paper, METRICS and BASELINE VALIDATION step 4): the
//! ground-truth plan is executed task by task by the policy; success is checked after every
//! action; each task has a sim-time limit (120 s); the completion time is recorded.
//!
//! This is the single code path behind `kitchen-r eval`, the server's workers and trajectory
//! collection, so a participant's local number and the leaderboard's are the same number.

use std::time::{Duration, Instant};

use kitchen_r_sim::task::TaskTarget;
use kitchen_r_sim::{Action, Observation, Sim, SimError, Snapshot, StepInfo};
use serde::{Deserialize, Serialize};

use crate::policy::{Policy, PolicyError, PolicyInput, Privileged, PrivilegedObject, validate_chunk};

/// How an episode is run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunOptions {
    /// Sim seconds each task may take (the paper: 120).
    pub task_time_limit: f64,
    /// Actions of each chunk executed before the policy is asked again.
    pub execute: usize,
    /// Execute only the first N plan steps (the paper's option); `None` = all.
    pub max_tasks: Option<usize>,
    /// Hand the policy privileged world state (organiser reference runs only).
    pub privileged: bool,
    /// Abort the episode after this many successive policy timeouts.
    pub max_consecutive_timeouts: u32,
    /// Wall-clock budget for the whole episode.
    pub wall_budget: Option<Duration>,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            task_time_limit: 120.0,
            execute: 8,
            max_tasks: None,
            privileged: false,
            max_consecutive_timeouts: 3,
            wall_budget: None,
        }
    }
}

/// What the runner observed of one task: richer than what scoring reads (failed tasks keep the
/// time they took, the policy calls, whether the failure ended the episode). The worker turns
/// it into the one scored shape, `kitchen_r_core::scoring::TaskOutcome`, at the wire.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskRecord {
    pub index: usize,
    pub step: String,
    pub success: bool,
    /// Sim seconds to success, or spent before failing.
    pub sim_time: f64,
    /// Why the task failed; `None` when it succeeded.
    pub failure: Option<String>,
    /// The failure ends the whole episode (wall budget, successive timeouts, the hook's abort):
    /// every later task fails with the same reason.
    #[serde(default)]
    pub aborts_episode: bool,
    pub policy_calls: u32,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeOutcome {
    pub episode_id: String,
    pub scene: String,
    pub tasks: Vec<TaskRecord>,
    pub sim_time: f64,
    pub wall_time_s: f64,
    pub policy_calls: u32,
}

impl EpisodeOutcome {
    /// Mean SR_j over the episode's tasks.
    pub fn success_rate(&self) -> f64 {
        if self.tasks.is_empty() {
            return 0.0;
        }
        self.tasks.iter().filter(|t| t.success).count() as f64 / self.tasks.len() as f64
    }
}

/// Observes every executed action, e.g. to record a trajectory; an `Err` aborts the episode
/// with that reason (the recording-rate monitor uses it).
pub trait StepHook {
    fn on_step(&mut self, sim: &Sim, action: &Action, info: &StepInfo) -> Result<(), String>;
    /// Whether the hook needs the rendered observation of every step (a recorder does); it then
    /// gets it through [`StepHook::observation`] just before `on_step`, rendered once and shared
    /// with the policy.
    fn wants_observation(&self) -> bool {
        false
    }
    fn observation(&mut self, _obs: &Observation) {}

    /// Called before task `index` begins, with the world as the task will find it: the
    /// expert-start snapshots behind teleport-on-failure are taken here.
    fn on_task_start(&mut self, _sim: &Sim, _index: usize) {}
}

impl StepHook for () {
    fn on_step(&mut self, _: &Sim, _: &Action, _: &StepInfo) -> Result<(), String> {
        Ok(())
    }
}

/// The platform failed (not the policy): the episode must be retried, never scored.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
}

/// Privileged state for reference policies.
fn privileged(sim: &Sim, target: TaskTarget) -> Privileged {
    let models = &sim.episode().objects;
    Privileged {
        scene: sim.episode().scene.clone(),
        base_pose: sim.base_pose(),
        objects: sim
            .object_poses()
            .into_iter()
            .zip(models)
            .map(|((name, iso), placement)| {
                let t = iso.translation.vector;
                let q = iso.rotation;
                PrivilegedObject {
                    name,
                    model: placement.model.clone(),
                    pose: [t.x, t.y, t.z, q.w, q.i, q.j, q.k],
                }
            })
            .collect(),
        held: sim.held_object().map(str::to_string),
        ee_pose: {
            let ee = sim.ee_pose();
            let (t, q) = (ee.translation.vector, ee.rotation);
            [t.x, t.y, t.z, q.w, q.i, q.j, q.k]
        },
        target,
    }
}

/// Run the episode already loaded in `sim` (after `reset`) with `policy`.
///
/// `expert_starts`, when given, holds the expert's state at the start of each task: after a
/// failed task the robot and objects are teleported there, so later tasks still count.
pub fn run_episode(
    sim: &mut Sim,
    policy: &mut dyn Policy,
    opts: &RunOptions,
    expert_starts: Option<&[Snapshot]>,
    hook: &mut dyn StepHook,
) -> Result<EpisodeOutcome, RunError> {
    let started = Instant::now();
    let episode = sim.episode().clone();
    let n_tasks = opts
        .max_tasks
        .map_or(episode.plan.len(), |m| m.min(episode.plan.len()));
    let mut out = EpisodeOutcome {
        episode_id: episode.id.clone(),
        scene: episode.scene.clone(),
        tasks: Vec::with_capacity(n_tasks),
        sim_time: 0.0,
        wall_time_s: 0.0,
        policy_calls: 0,
    };
    let mut timeouts = 0u32;
    let mut aborted: Option<String> = None;
    for j in 0..n_tasks {
        let step_text = episode.plan[j].clone();
        if let Some(reason) = &aborted {
            out.tasks.push(TaskRecord {
                aborts_episode: true,
                ..failed(j, step_text, 0.0, reason.clone(), 0)
            });
            continue;
        }
        let task = run_task(sim, policy, opts, j, &mut timeouts, hook, started)?;
        out.policy_calls += task.policy_calls;
        if task.aborts_episode {
            aborted = task.failure.clone();
        }
        let failed_task = !task.success;
        out.tasks.push(task);
        if failed_task
            && aborted.is_none()
            && let Some(snap) = expert_starts.and_then(|s| s.get(j + 1))
        {
            sim.restore(snap)?;
        }
    }
    out.sim_time = sim.time();
    out.wall_time_s = started.elapsed().as_secs_f64();
    Ok(out)
}

/// How the reason of a failure that ends the whole episode starts, for the reader (the runner
/// itself goes by [`TaskRecord::aborts_episode`]).
const ABORT: &str = "episode aborted: ";

fn failed(index: usize, step: String, sim_time: f64, reason: String, calls: u32) -> TaskRecord {
    TaskRecord {
        index,
        step,
        success: false,
        sim_time,
        failure: Some(reason),
        aborts_episode: false,
        policy_calls: calls,
    }
}

fn run_task(
    sim: &mut Sim,
    policy: &mut dyn Policy,
    opts: &RunOptions,
    j: usize,
    timeouts: &mut u32,
    hook: &mut dyn StepHook,
    episode_started: Instant,
) -> Result<TaskRecord, RunError> {
    let step_text = sim.episode().plan[j].clone();
    let episode_id = sim.episode().id.clone();
    hook.on_task_start(sim, j);
    sim.begin_task(j)?;
    let target = kitchen_r_sim::task_target(sim.episode(), sim.scene(), j)?;
    let t0 = sim.time();
    let mut calls = 0u32;
    let fail = |sim: &mut Sim, reason: String, calls: u32| {
        let elapsed = sim.time() - t0;
        sim.end_task();
        Ok(failed(j, step_text.clone(), elapsed, reason, calls))
    };
    let abort = |sim: &mut Sim, reason: String, calls: u32| {
        let elapsed = sim.time() - t0;
        sim.end_task();
        Ok(TaskRecord {
            aborts_episode: true,
            ..failed(j, step_text.clone(), elapsed, format!("{ABORT}{reason}"), calls)
        })
    };
    if let Err(e) = policy.reset(&episode_id, j, &step_text) {
        return fail(sim, format!("reset: {e}"), calls);
    }
    let mut obs: Observation = if policy.wants_images() || hook.wants_observation() {
        sim.observe()
    } else {
        sim.observe_state()
    };
    loop {
        if opts.wall_budget.is_some_and(|b| episode_started.elapsed() > b) {
            return abort(sim, "wall-clock budget exceeded".into(), calls);
        }
        let privileged = opts.privileged.then(|| privileged(sim, target.clone()));
        let input = PolicyInput {
            episode_id: &episode_id,
            step: sim_step(sim),
            task_index: j,
            sub_task: &step_text,
            observation: &obs,
            privileged: privileged.as_ref(),
        };
        calls += 1;
        let chunk = match policy.act(&input).and_then(|c| {
            validate_chunk(&c, policy.spec().horizon)?;
            Ok(c)
        }) {
            Ok(c) => {
                *timeouts = 0;
                c
            }
            Err(PolicyError::Timeout(s)) => {
                *timeouts += 1;
                let reason = PolicyError::Timeout(s).to_string();
                if *timeouts >= opts.max_consecutive_timeouts {
                    return abort(
                        sim,
                        format!("{} successive timeouts ({reason})", *timeouts),
                        calls,
                    );
                }
                return fail(sim, reason, calls);
            }
            Err(e) => return fail(sim, e.to_string(), calls),
        };
        let k = opts.execute.clamp(1, chunk.len());
        let hook_watches = hook.wants_observation();
        for (i, a) in chunk[..k].iter().enumerate() {
            let action = Action(*a);
            // The policy is asked again after the last action of the part-chunk.
            let query = i + 1 == k;
            let render = hook_watches || (query && policy.wants_images());
            let (o, info) = sim.step(&action, render)?;
            if let Some(o) = &o
                && hook_watches
            {
                hook.observation(o);
            }
            if let Err(reason) = hook.on_step(sim, &action, &info) {
                return abort(sim, reason, calls);
            }
            let elapsed = sim.time() - t0;
            if info.task.as_ref().is_some_and(|t| t.success) {
                sim.end_task();
                return Ok(TaskRecord {
                    index: j,
                    step: step_text,
                    success: true,
                    sim_time: elapsed,
                    failure: None,
                    aborts_episode: false,
                    policy_calls: calls,
                });
            }
            if elapsed >= opts.task_time_limit - 1e-9 {
                return fail(
                    sim,
                    format!("time limit of {} s reached", opts.task_time_limit),
                    calls,
                );
            }
            if query {
                obs = o.unwrap_or_else(|| sim.observe_state());
            }
        }
    }
}

/// Control steps since reset, from sim time (the sim counts substeps).
fn sim_step(sim: &Sim) -> u64 {
    (sim.time() / sim.config().physics.control_dt + 0.5) as u64
}
