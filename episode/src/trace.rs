//! Episode traces (docs/twin/replay.md): what reproduces an online episode exactly, so its video
//! can be rendered later, on demand, instead of during evaluation.
//!
//! Episodes are bit-reproducible: the simulator is deterministic and the runner's decisions
//! depend only on the episode's configuration, the run's options and what the policy answered.
//! A [`Trace`] holds exactly those (a few tens to hundreds of KB of JSON), plus the outcome the
//! run reported. [`fn@replay`] runs the episode again from it, with the policy's answers played
//! back by a [`ReplayPolicy`], and refuses ([`ReplayError::Disagrees`]) unless every task's
//! success, sim time (bit for bit) and failure text match the stored outcome: whatever a
//! replay renders is shown only when it is the episode that was scored.
//!
//! Chunks are recorded as the policy returned them, before the runner's `check_chunk`, so
//! the replay corrects (or refuses) them exactly as the run did. The one input of a run that is
//! not in the policy's answers is real time: the episode's wall-clock budget. A trace records
//! where it ran out ([`Trace::budget_abort_at`]) and the replay ends the episode at that decision
//! ([`RunOptions::budget_abort_at`]).

use std::path::Path;

use kitchen_r_core::GraspMode;
use kitchen_r_sim::EpisodeConfig;
use serde::{Deserialize, Serialize};

use crate::policy::{
    ACTION_DIM, ChunkTolerance, Policy, PolicyError, PolicyInput, PolicySpec, PrivilegedScope,
};
use crate::runner::{Decision, EpisodeOutcome, RunOptions, TaskRecord, ran_out_of_budget};

pub mod gzip;
mod number;
mod replay;

pub use replay::{ReplayError, ReplayPolicy, replay, replay_config, replay_with};

/// The `format` tag every trace file carries.
pub const FORMAT: &str = "kitchen-r-trace";
/// The trace layout this build writes and reads.
pub const VERSION: u32 = 1;

/// The file name of an episode's trace: `<episode key>.trace.json`.
pub fn file_name(episode_key: &str) -> String {
    format!("{episode_key}.trace.json")
}

/// Everything that reproduces one online episode; see the module doc.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Trace {
    /// [`FORMAT`].
    pub format: String,
    /// [`VERSION`].
    pub version: u32,
    /// The episode as the simulator was reset to it.
    pub episode: EpisodeConfig,
    pub run: TraceRun,
    pub policy: TracePolicy,
    /// Every answer of the policy, in call order.
    pub calls: Vec<Call>,
    /// Where the episode's wall-clock budget ran out, if it did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub budget_abort_at: Option<Decision>,
    /// What the run reported; a replay must reproduce it bit for bit.
    pub outcome: TraceOutcome,
}

/// The run's options that decide what happens in an episode ([`RunOptions`] less real time).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TraceRun {
    pub task_time_limit: f64,
    pub execute: usize,
    pub max_tasks: Option<usize>,
    /// Teleport on failure: the expert's state at each task's start, from the oracle's
    /// pre-run over the episode ([`crate::teleport::expert_starts`]).
    pub expert_starts: bool,
    /// Privileged world state handed to the policy (organiser reference runs).
    pub privileged: bool,
    /// The privileged track's observation scope; `None` on the standard track.
    pub privileged_observations: Option<PrivilegedScope>,
    pub chunk_tolerance: ChunkTolerance,
    pub max_consecutive_timeouts: u32,
    /// The simulator's grasp mode (docs/twin/robot.md): a replay runs in it whatever its own
    /// `[grasp] mode` says. Absent from traces recorded before it existed, which ran the
    /// abstract grasp, and left out of abstract traces so older builds still replay them (a
    /// physical trace is refused by a build that does not know the field, never replayed in the
    /// wrong mode).
    #[serde(default, skip_serializing_if = "is_abstract")]
    pub grasp: GraspMode,
}

fn is_abstract(m: &GraspMode) -> bool {
    *m == GraspMode::Abstract
}

impl TraceRun {
    pub fn new(run: &RunOptions, grasp: GraspMode, expert_starts: bool) -> TraceRun {
        TraceRun {
            grasp,
            task_time_limit: run.task_time_limit,
            execute: run.execute,
            max_tasks: run.max_tasks,
            expert_starts,
            privileged: run.privileged,
            privileged_observations: run.privileged_observations,
            chunk_tolerance: run.chunk_tolerance,
            max_consecutive_timeouts: run.max_consecutive_timeouts,
        }
    }

    /// The options a replay runs with: no real-time budget, the recorded abort instead.
    pub fn options(&self, budget_abort_at: Option<Decision>) -> RunOptions {
        RunOptions {
            task_time_limit: self.task_time_limit,
            execute: self.execute,
            max_tasks: self.max_tasks,
            privileged: self.privileged,
            privileged_observations: self.privileged_observations,
            max_consecutive_timeouts: self.max_consecutive_timeouts,
            wall_budget: None,
            chunk_tolerance: self.chunk_tolerance,
            budget_abort_at,
        }
    }
}

/// What the runner reads of the policy's [`PolicySpec`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TracePolicy {
    /// For the reader only.
    pub name: String,
    pub horizon: usize,
    pub observation_history: usize,
    pub actions_executed_per_chunk: Option<usize>,
    /// For the reader only: a replay renders no frame for the policy, since rendering reads
    /// the world without changing it.
    pub wants_images: bool,
}

impl TracePolicy {
    fn of(policy: &dyn Policy) -> TracePolicy {
        let s = policy.spec();
        TracePolicy {
            name: s.name.clone(),
            horizon: s.horizon,
            observation_history: s.observation_history,
            actions_executed_per_chunk: s.actions_executed_per_chunk,
            wants_images: policy.wants_images(),
        }
    }

    pub(crate) fn spec(&self) -> PolicySpec {
        PolicySpec {
            name: self.name.clone(),
            horizon: self.horizon,
            observation_history: self.observation_history,
            actions_executed_per_chunk: self.actions_executed_per_chunk,
            ..PolicySpec::default()
        }
    }
}

/// One answer of the policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Call {
    /// `reset` for plan step `task`; `error` when it failed.
    Reset {
        task: usize,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        error: Option<PolicyError>,
    },
    /// `act` at control step `step` of plan step `task`: the chunk as returned (before the
    /// runner's checks and corrections), or the error.
    Act {
        task: usize,
        step: u64,
        #[serde(default, skip_serializing_if = "Option::is_none", with = "number::chunk")]
        chunk: Option<Vec<[f64; ACTION_DIM]>>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        error: Option<PolicyError>,
    },
}

/// The outcome a replay is checked against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TraceOutcome {
    pub tasks: Vec<TaskCheck>,
    /// Sim seconds at the episode's end.
    pub sim_time: f64,
}

/// One task's outcome as a replay must reproduce it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskCheck {
    pub index: usize,
    pub success: bool,
    /// Exact: JSON numbers round-trip f64 bits (serde_json's `float_roundtrip`).
    pub sim_time: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
    pub policy_calls: u32,
}

impl TaskCheck {
    fn of(t: &TaskRecord) -> TaskCheck {
        TaskCheck {
            index: t.index,
            success: t.success,
            sim_time: t.sim_time,
            failure: t.failure.clone(),
            policy_calls: t.policy_calls,
        }
    }
}

impl TraceOutcome {
    pub fn of(o: &EpisodeOutcome) -> TraceOutcome {
        TraceOutcome {
            tasks: o.tasks.iter().map(TaskCheck::of).collect(),
            sim_time: o.sim_time,
        }
    }
}

impl Trace {
    /// The trace as pretty-free JSON (one line; chunks dominate its size).
    pub fn to_json(&self) -> Vec<u8> {
        // Serialising plain data to memory cannot fail: non-finite numbers are written as strings.
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// A trace read back, refused unless it is one this build can replay.
    pub fn from_json(bytes: &[u8]) -> Result<Trace, ReplayError> {
        #[derive(Deserialize)]
        struct Tag {
            format: String,
            version: u32,
        }
        let tag: Tag = serde_json::from_slice(bytes)
            .map_err(|e| ReplayError::Format(format!("not a Kitchen-R trace: {e}")))?;
        if tag.format != FORMAT || tag.version != VERSION {
            return Err(ReplayError::Format(format!(
                "{} version {} is not a trace this build replays ({FORMAT} version {VERSION})",
                tag.format, tag.version
            )));
        }
        serde_json::from_slice(bytes).map_err(|e| ReplayError::Format(format!("trace: {e}")))
    }

    /// The trace as gzipped JSON, the form workers upload and the server stores (an oracle
    /// episode's 218 KB of JSON is about 31 KB gzipped).
    pub fn to_json_gz(&self) -> Vec<u8> {
        gzip::compress(&self.to_json())
    }

    /// A trace from JSON or gzipped JSON (told apart by the gzip magic number).
    pub fn from_bytes(bytes: &[u8]) -> Result<Trace, ReplayError> {
        match gzip::is_gzip(bytes) {
            true => Trace::from_json(&gzip::decompress(bytes).map_err(ReplayError::Format)?),
            false => Trace::from_json(bytes),
        }
    }

    /// Write the trace to `path`.
    pub fn save(&self, path: &Path) -> Result<(), String> {
        std::fs::write(path, self.to_json()).map_err(|e| format!("writing the trace {}: {e}", path.display()))
    }

    /// Read the trace at `path`: JSON, or gzipped JSON as the server serves it.
    pub fn load(path: &Path) -> Result<Trace, ReplayError> {
        let bytes = std::fs::read(path)
            .map_err(|e| ReplayError::Format(format!("reading {}: {e}", path.display())))?;
        Trace::from_bytes(&bytes).map_err(|e| ReplayError::Format(format!("{}: {e}", path.display())))
    }
}

/// Wraps any policy and records its every answer (see the module doc); [`Self::into_trace`]
/// turns the record and the run's outcome into a [`Trace`].
pub struct TracingPolicy<P> {
    inner: P,
    calls: Vec<Call>,
}

impl<P: Policy> TracingPolicy<P> {
    pub fn new(inner: P) -> TracingPolicy<P> {
        TracingPolicy {
            inner,
            calls: Vec::new(),
        }
    }

    /// The trace of the episode this policy was run in: `episode` as loaded, `run` as given to
    /// the runner, `grasp` the simulator's grasp mode, `expert_starts` whether it had teleport
    /// starts, `outcome` what it returned.
    pub fn into_trace(
        self,
        episode: EpisodeConfig,
        run: &RunOptions,
        grasp: GraspMode,
        expert_starts: bool,
        outcome: &EpisodeOutcome,
    ) -> Trace {
        let budget_abort_at = outcome
            .tasks
            .iter()
            .find(|t| ran_out_of_budget(t))
            .map(|t| Decision {
                task: t.index,
                calls: t.policy_calls,
            });
        Trace {
            format: FORMAT.to_string(),
            version: VERSION,
            episode,
            run: TraceRun::new(run, grasp, expert_starts),
            policy: TracePolicy::of(&self.inner),
            calls: self.calls,
            budget_abort_at,
            outcome: TraceOutcome::of(outcome),
        }
    }
}

impl<P: Policy> Policy for TracingPolicy<P> {
    fn spec(&self) -> &PolicySpec {
        self.inner.spec()
    }

    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        let r = self.inner.reset(episode_id, task_index, sub_task);
        self.calls.push(Call::Reset {
            task: task_index,
            error: r.clone().err(),
        });
        r
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let r = self.inner.act(input);
        let (chunk, error) = match &r {
            Ok(c) => (Some(c.clone()), None),
            Err(e) => (None, Some(e.clone())),
        };
        self.calls.push(Call::Act {
            task: input.task_index,
            step: input.step,
            chunk,
            error,
        });
        r
    }

    fn wants_images(&self) -> bool {
        self.inner.wants_images()
    }
}

#[cfg(test)]
mod tests;
