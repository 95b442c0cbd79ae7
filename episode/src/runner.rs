//! Online evaluation of one episode (paper, METRICS and BASELINE VALIDATION step 4): the
//! ground-truth plan is executed task by task by the policy; success is checked after every
//! action; each task has a sim-time limit (120 s); the completion time is recorded.
//!
//! This is the single code path behind `kitchen-r eval`, the server's workers and trajectory
//! collection, so a participant's local number and the leaderboard's are the same number.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use kitchen_r_sim::task::TaskTarget;
use kitchen_r_sim::{Action, Observation, Sim, SimError, Snapshot, StepInfo};
use serde::{Deserialize, Serialize};

use crate::policy::{
    ACTION_DIM, ChunkTolerance, Corrections, Frame, MAX_OBSERVATION_HISTORY, Policy, PolicyError,
    PolicyInput, Privileged, PrivilegedObject, PrivilegedObservation, PrivilegedScope, check_chunk,
};

/// How an episode is run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunOptions {
    /// Sim seconds each task may take (the paper: 120).
    pub task_time_limit: f64,
    /// Actions of each chunk executed before the policy is asked again, unless the policy
    /// chose its own count ([`crate::policy::PolicySpec::actions_executed_per_chunk`]).
    pub execute: usize,
    /// Execute only the first N plan steps (the paper's option); `None` = all.
    pub max_tasks: Option<usize>,
    /// Hand the policy privileged world state (organiser reference runs only).
    pub privileged: bool,
    /// The privileged track: hand the policy a privileged observation of this scope at every
    /// decision ([`crate::policy::privileged`]); `None` on the standard track.
    #[serde(default)]
    pub privileged_observations: Option<PrivilegedScope>,
    /// Abort the episode after this many successive policy timeouts.
    pub max_consecutive_timeouts: u32,
    /// Wall-clock budget for the whole episode, less what the hook spends on its own
    /// ([`StepHook::overhead`]: recording a video must not cost the policy its budget).
    pub wall_budget: Option<Duration>,
    /// How far a chunk may be off before it fails the task; slips within are corrected.
    #[serde(default)]
    pub chunk_tolerance: ChunkTolerance,
    /// Replays only ([`crate::trace`]): end the episode for its wall-clock budget at exactly
    /// this decision, where the recorded run's real clock ran out. A replay has no real time
    /// to measure (it runs faster or slower than the run it reproduces), so it is told where.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget_abort_at: Option<Decision>,
}

/// A decision point of an episode: before policy call `calls + 1` of plan step `task`
/// (`calls` = the calls the task had made, as [`TaskRecord::policy_calls`] counts them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Decision {
    pub task: usize,
    pub calls: u32,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            task_time_limit: 120.0,
            execute: 8,
            max_tasks: None,
            privileged: false,
            privileged_observations: None,
            max_consecutive_timeouts: 3,
            wall_budget: None,
            chunk_tolerance: ChunkTolerance::default(),
            budget_abort_at: None,
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
    /// Chunk values corrected within tolerance during the task (a warning, not a failure).
    #[serde(default)]
    pub corrections: Corrections,
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

    /// Called when a task that ran has ended, with its record (before any teleport to the next
    /// task's start): an episode video captions the outcome here.
    fn on_task_end(&mut self, _sim: &Sim, _task: &TaskRecord) {}

    /// Wall time the hook itself has spent so far (an episode video's encoding): the episode's
    /// wall budget is the policy's, so it does not count this.
    fn overhead(&self) -> Duration {
        Duration::ZERO
    }
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
    /// A run from plan step N needs the expert's state at its start, and none was given (or
    /// the plan has no step N).
    #[error("no expert state at the start of plan step {0} to start from")]
    NoStart(usize),
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
        ee_pose: ee_pose(sim),
        target,
    }
}

/// What a policy on the privileged track is shown of `world` (nothing on the standard track).
pub(crate) fn privileged_observation(
    world: Option<&Privileged>,
    scope: Option<PrivilegedScope>,
) -> Option<PrivilegedObservation> {
    PrivilegedObservation::from_world(world?, scope?)
}

/// The hand (tool centre point) pose in the base frame `[x, y, z, qw, qx, qy, qz]`.
pub fn ee_pose(sim: &Sim) -> [f64; 7] {
    let ee = sim.ee_pose();
    let (t, q) = (ee.translation.vector, ee.rotation);
    [t.x, t.y, t.z, q.w, q.i, q.j, q.k]
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
    run_from_task(sim, policy, opts, expert_starts, hook, 0)
}

/// [`run_episode`] from plan step `first` on: the robot and objects are first put where the
/// expert stood at that task's start (`expert_starts[first]`), and only tasks `first..` are
/// run and reported (one sub-task as an episode: `KitchenR/Task-v0`, with `max_tasks` =
/// `first + 1`). `first = 0` is `run_episode`.
pub fn run_from_task(
    sim: &mut Sim,
    policy: &mut dyn Policy,
    opts: &RunOptions,
    expert_starts: Option<&[Snapshot]>,
    hook: &mut dyn StepHook,
    first: usize,
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
    let mut last_action: Option<[f64; ACTION_DIM]> = None;
    if first > 0 {
        let snap = (expert_starts.and_then(|s| s.get(first))).ok_or(RunError::NoStart(first))?;
        sim.restore(snap)?;
    }
    for j in first..n_tasks {
        let step_text = episode.plan[j].clone();
        if let Some(reason) = &aborted {
            out.tasks.push(TaskRecord {
                aborts_episode: true,
                ..failed(j, step_text, 0.0, reason.clone(), 0)
            });
            continue;
        }
        let mut state = EpisodeState {
            timeouts: &mut timeouts,
            last_action: &mut last_action,
            started,
        };
        let task = run_task(sim, policy, opts, j, &mut state, hook)?;
        hook.on_task_end(sim, &task);
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
            // The robot was moved: no action of the policy led to this state.
            last_action = None;
        }
    }
    out.sim_time = sim.time();
    out.wall_time_s = started.elapsed().as_secs_f64();
    Ok(out)
}

/// How the reason of a failure that ends the whole episode starts, for the reader (the runner
/// itself goes by [`TaskRecord::aborts_episode`]).
const ABORT: &str = "episode aborted: ";

/// Why the wall-clock budget ended an episode (after [`ABORT`]); a trace finds the decision it
/// happened at by it.
pub(crate) const OVER_BUDGET: &str = "wall-clock budget exceeded";

/// Whether `task` failed because the episode ran out of its wall-clock budget (the task the
/// budget ran out in; later tasks only inherit the reason).
pub(crate) fn ran_out_of_budget(task: &TaskRecord) -> bool {
    task.aborts_episode && task.failure.as_deref() == Some(&format!("{ABORT}{OVER_BUDGET}"))
}

fn failed(index: usize, step: String, sim_time: f64, reason: String, calls: u32) -> TaskRecord {
    TaskRecord {
        index,
        step,
        success: false,
        sim_time,
        failure: Some(reason),
        aborts_episode: false,
        policy_calls: calls,
        corrections: Corrections::default(),
    }
}

/// What one task's run shares with the rest of its episode.
struct EpisodeState<'a> {
    timeouts: &'a mut u32,
    /// The last action executed, the next frame's `previous_action`.
    last_action: &'a mut Option<[f64; ACTION_DIM]>,
    started: Instant,
}

/// The frames the next decision shows: the last `cap` captured control steps of the task,
/// oldest first. Only the steps a decision will show are captured (rendered), so when the
/// history is longer than a part-chunk the frames span earlier chunks of the task.
struct History {
    frames: VecDeque<Frame>,
    cap: usize,
}

impl History {
    fn push(&mut self, sim: &Sim, observation: Observation, previous_action: Option<[f64; ACTION_DIM]>) {
        if self.frames.len() == self.cap {
            self.frames.pop_front();
        }
        self.frames.push_back(Frame {
            step: sim_step(sim),
            observation,
            ee_pose: ee_pose(sim),
            previous_action,
        });
    }
}

fn run_task(
    sim: &mut Sim,
    policy: &mut dyn Policy,
    opts: &RunOptions,
    j: usize,
    ep: &mut EpisodeState<'_>,
    hook: &mut dyn StepHook,
) -> Result<TaskRecord, RunError> {
    let step_text = sim.episode().plan[j].clone();
    let episode_id = sim.episode().id.clone();
    hook.on_task_start(sim, j);
    sim.begin_task(j)?;
    let target = kitchen_r_sim::task_target(sim.episode(), sim.scene(), j)?;
    let t0 = sim.time();
    let mut calls = 0u32;
    let mut corrections = Corrections::default();
    // `failure`: the reason and whether it ends the episode; `None` = success.
    let end = |sim: &mut Sim, failure: Option<(String, bool)>, calls: u32, corrections: Corrections| {
        let elapsed = sim.time() - t0;
        sim.end_task();
        let (failure, aborts_episode) = match failure {
            None => (None, false),
            Some((reason, true)) => (Some(format!("{ABORT}{reason}")), true),
            Some((reason, false)) => (Some(reason), false),
        };
        Ok::<_, RunError>(TaskRecord {
            index: j,
            step: step_text.clone(),
            success: failure.is_none(),
            sim_time: elapsed,
            failure,
            aborts_episode,
            policy_calls: calls,
            corrections,
        })
    };
    if let Err(e) = policy.reset(&episode_id, j, &step_text) {
        return end(sim, Some((format!("reset: {e}"), false)), calls, corrections);
    }
    let spec = policy.spec();
    let (horizon, cap) = (
        spec.horizon,
        spec.observation_history.clamp(1, MAX_OBSERVATION_HISTORY),
    );
    let per_chunk = spec.actions_executed_per_chunk.unwrap_or(opts.execute);
    let mut history = History {
        frames: VecDeque::with_capacity(cap),
        cap,
    };
    let first = if policy.wants_images() || hook.wants_observation() {
        sim.observe()
    } else {
        sim.observe_state()
    };
    history.push(sim, first, *ep.last_action);
    loop {
        let spent = ep.started.elapsed().saturating_sub(hook.overhead());
        let here = Decision { task: j, calls };
        if opts.wall_budget.is_some_and(|b| spent > b) || opts.budget_abort_at == Some(here) {
            let why = OVER_BUDGET.to_string();
            return end(sim, Some((why, true)), calls, corrections);
        }
        let world = (opts.privileged || opts.privileged_observations.is_some())
            .then(|| privileged(sim, target.clone()));
        let shown = privileged_observation(world.as_ref(), opts.privileged_observations);
        let privileged = world.filter(|_| opts.privileged);
        let (newest, earlier) = match history.frames.make_contiguous().split_last() {
            Some(split) => split,
            None => return end(sim, Some(("no observation".into(), false)), calls, corrections),
        };
        let input = PolicyInput {
            episode_id: &episode_id,
            step: newest.step,
            task_index: j,
            sub_task: &step_text,
            observation: &newest.observation,
            ee_pose: newest.ee_pose,
            previous_action: newest.previous_action,
            history: earlier,
            privileged: privileged.as_ref(),
            privileged_observation: shown.as_ref(),
        };
        calls += 1;
        let answer = policy.act(&input).and_then(|mut c| {
            let fixed = check_chunk(&mut c, horizon, &opts.chunk_tolerance)?;
            Ok((c, fixed))
        });
        let chunk = match answer {
            Ok((c, fixed)) => {
                *ep.timeouts = 0;
                corrections.add(&fixed);
                c
            }
            Err(PolicyError::Timeout(s)) => {
                *ep.timeouts += 1;
                let reason = PolicyError::Timeout(s).to_string();
                if *ep.timeouts >= opts.max_consecutive_timeouts {
                    let why = format!("{} successive timeouts ({reason})", *ep.timeouts);
                    return end(sim, Some((why, true)), calls, corrections);
                }
                return end(sim, Some((reason, false)), calls, corrections);
            }
            Err(e) => return end(sim, Some((e.to_string(), false)), calls, corrections),
        };
        let k = per_chunk.clamp(1, chunk.len());
        let hook_watches = hook.wants_observation();
        for (i, a) in chunk[..k].iter().enumerate() {
            let action = Action(*a);
            // The policy is asked again after the last action of the part-chunk and sees the
            // last `cap` steps: only those are captured, and rendered only if it wants images,
            // after the step proved not to end the task (the hook's frames are rendered anyway).
            let capture = i + cap >= k;
            let (o, info) = sim.step(&action, hook_watches)?;
            *ep.last_action = Some(*a);
            if let Some(o) = &o
                && hook_watches
            {
                hook.observation(o);
            }
            if let Err(reason) = hook.on_step(sim, &action, &info) {
                return end(sim, Some((reason, true)), calls, corrections);
            }
            let elapsed = sim.time() - t0;
            if info.task.as_ref().is_some_and(|t| t.success) {
                return end(sim, None, calls, corrections);
            }
            if elapsed >= opts.task_time_limit - 1e-9 {
                let mut why = format!("time limit of {} s reached", opts.task_time_limit);
                if let Some(gap) = sim.task_shortfall() {
                    why = format!("{why}: {gap}");
                }
                return end(sim, Some((why, false)), calls, corrections);
            }
            if capture {
                let obs = match o {
                    Some(o) => o,
                    None if policy.wants_images() => sim.observe(),
                    None => sim.observe_state(),
                };
                history.push(sim, obs, Some(*a));
            }
        }
    }
}

/// Control steps since reset, from sim time (the sim counts substeps).
fn sim_step(sim: &Sim) -> u64 {
    (sim.time() / sim.config().physics.control_dt + 0.5) as u64
}
