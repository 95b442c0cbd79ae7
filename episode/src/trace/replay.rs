//! Running a trace's episode again ([`replay`]) and checking it is the episode that was run.

use kitchen_r_sim::{Assets, SensorsConfig, Sim, SimConfig, SimError};

use super::{Call, TaskCheck, Trace, TraceOutcome};
use crate::policy::{ACTION_DIM, Policy, PolicyError, PolicyInput, PolicySpec};
use crate::runner::{EpisodeOutcome, RunError, StepHook, TaskRecord, run_episode};
use crate::sim_slot::load;
use crate::teleport::expert_starts;

/// Why a trace was not replayed, or its replay must not be shown.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// Not a trace this build reads.
    #[error("{0}")]
    Format(String),
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("{0}")]
    Run(#[from] RunError),
    /// The replay is not the episode the trace recorded: the policy was asked something the
    /// run did not ask it, or the outcome differs. Nothing rendered from it may be shown.
    #[error("the replay disagrees with the recorded episode: {what}")]
    Disagrees { what: String },
}

/// Answers from a trace's recorded calls, in order, and notes the first call that differs from
/// the recorded one (a different plan step or control step: the replay went another way).
pub struct ReplayPolicy {
    spec: PolicySpec,
    calls: Vec<Call>,
    next: usize,
    diverged: Option<String>,
}

impl ReplayPolicy {
    pub fn new(trace: &Trace) -> ReplayPolicy {
        ReplayPolicy {
            spec: trace.policy.spec(),
            calls: trace.calls.clone(),
            next: 0,
            diverged: None,
        }
    }

    /// Every recorded call was made, as recorded; else what differed first.
    pub fn finish(&self) -> Result<(), String> {
        if let Some(d) = &self.diverged {
            return Err(d.clone());
        }
        match self.calls.len() - self.next {
            0 => Ok(()),
            n => Err(format!(
                "the replay ended with {n} recorded policy call(s) not made"
            )),
        }
    }

    /// The next recorded call, or the divergence (also kept for [`Self::finish`]) as the
    /// policy's error: the runner fails the task with it, and the replay is refused anyway.
    fn take(&mut self, asked: &str) -> Result<Call, PolicyError> {
        if self.diverged.is_none() {
            match self.calls.get(self.next) {
                Some(c) => {
                    self.next += 1;
                    return Ok(c.clone());
                }
                None => {
                    let why = format!("call {} ({asked}) was never made in the run", self.next);
                    self.diverged = Some(why);
                }
            }
        }
        Err(diverged())
    }

    fn diverge(&mut self, asked: &str, recorded: &Call) -> PolicyError {
        let why = format!(
            "call {}: the replay asked {asked}, the run recorded {}",
            self.next - 1,
            describe(recorded)
        );
        self.diverged.get_or_insert(why);
        diverged()
    }
}

/// What the runner is told once the replay went its own way (the task fails; the replay is
/// refused by [`ReplayPolicy::finish`] whatever happens next).
fn diverged() -> PolicyError {
    PolicyError::Call("the replay diverged from its trace".into())
}

fn describe(c: &Call) -> String {
    match c {
        Call::Reset { task, .. } => format!("reset of task {task}"),
        Call::Act { task, step, .. } => format!("act at task {task} step {step}"),
    }
}

impl Policy for ReplayPolicy {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }

    fn reset(&mut self, _: &str, task_index: usize, _: &str) -> Result<(), PolicyError> {
        let asked = format!("reset of task {task_index}");
        match self.take(&asked)? {
            Call::Reset { task, error } if task == task_index => error.map_or(Ok(()), Err),
            other => Err(self.diverge(&asked, &other)),
        }
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let asked = format!("act at task {} step {}", input.task_index, input.step);
        match self.take(&asked)? {
            Call::Act {
                task,
                step,
                chunk,
                error,
            } if task == input.task_index && step == input.step => match (chunk, error) {
                (_, Some(e)) => Err(e),
                (Some(c), None) => Ok(c),
                (None, None) => Err(PolicyError::Call("the trace recorded no answer".into())),
            },
            other => Err(self.diverge(&asked, &other)),
        }
    }

    /// Rendering reads the world without changing it, so the policy's frames are not needed to
    /// reproduce the episode (a recording hook still gets its own).
    fn wants_images(&self) -> bool {
        false
    }
}

/// [`replay_with`] on the default assets and configs (those `eval` and the workers load).
pub fn replay(trace: &Trace, hook: &mut dyn StepHook) -> Result<EpisodeOutcome, ReplayError> {
    let assets = Assets::load_default()?;
    let (sim, sensors) = (SimConfig::load_default()?, SensorsConfig::load_default()?);
    replay_with(trace, &assets, &sim, &sensors, hook)
}

/// Run `trace`'s episode again, built as `eval` and the workers build it, with `hook` watching
/// (a video recorder), and check it reproduces the recorded outcome bit for bit. On
/// [`ReplayError::Disagrees`] whatever `hook` recorded must not be shown. The trace's grasp mode
/// overrides `sim_cfg`'s: an episode replays in the mode it ran in.
pub fn replay_with(
    trace: &Trace,
    assets: &Assets,
    sim_cfg: &SimConfig,
    sensors: &SensorsConfig,
    hook: &mut dyn StepHook,
) -> Result<EpisodeOutcome, ReplayError> {
    let sim_cfg = &replay_config(trace, sim_cfg);
    let mut slot: Option<Sim> = None;
    let sim = load(&mut slot, assets, sim_cfg, sensors, &trace.episode)?;
    let starts = match trace.run.expert_starts {
        true => Some(expert_starts(sim, &trace.episode, assets)?),
        false => None,
    };
    let mut policy = ReplayPolicy::new(trace);
    let run = trace.run.options(trace.budget_abort_at);
    let out = run_episode(sim, &mut policy, &run, starts.as_deref(), hook)?;
    policy.finish().map_err(|what| ReplayError::Disagrees { what })?;
    agrees(&trace.outcome, &out).map_err(|what| ReplayError::Disagrees { what })?;
    Ok(out)
}

/// The simulator configuration a trace replays with: `base` in the trace's grasp mode.
pub fn replay_config(trace: &Trace, base: &SimConfig) -> SimConfig {
    let mut cfg = base.clone();
    cfg.grasp.mode = trace.run.grasp;
    cfg
}

/// The first difference between the recorded outcome and the replayed one.
fn agrees(recorded: &TraceOutcome, replayed: &EpisodeOutcome) -> Result<(), String> {
    if recorded.tasks.len() != replayed.tasks.len() {
        return Err(format!(
            "{} task(s) recorded, {} replayed",
            recorded.tasks.len(),
            replayed.tasks.len()
        ));
    }
    for (r, p) in recorded.tasks.iter().zip(&replayed.tasks) {
        task_agrees(r, p).map_err(|d| format!("task {}: {d}", r.index))?;
    }
    same_bits("episode sim time", recorded.sim_time, replayed.sim_time)
}

fn task_agrees(r: &TaskCheck, p: &TaskRecord) -> Result<(), String> {
    if r.index != p.index {
        return Err(format!("index {} replayed as {}", r.index, p.index));
    }
    if r.success != p.success {
        return Err(format!("success {} replayed as {}", r.success, p.success));
    }
    same_bits("sim time", r.sim_time, p.sim_time)?;
    if r.failure != p.failure {
        return Err(format!("failure {:?} replayed as {:?}", r.failure, p.failure));
    }
    if r.policy_calls != p.policy_calls {
        return Err(format!(
            "{} policy calls replayed as {}",
            r.policy_calls, p.policy_calls
        ));
    }
    Ok(())
}

fn same_bits(what: &str, recorded: f64, replayed: f64) -> Result<(), String> {
    match recorded.to_bits() == replayed.to_bits() {
        true => Ok(()),
        false => Err(format!("{what} {recorded:?} s replayed as {replayed:?} s")),
    }
}
