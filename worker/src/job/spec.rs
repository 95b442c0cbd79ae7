//! A leased job's `EpisodeSpec` as the simulator's episode configuration and the runner's
//! options, derived exactly as `kitchen-r eval` derives them (the episode seed is
//! [`instruction_seed`] of the run seed and the instruction id), so a participant's local number
//! and the leaderboard's are the same number.
//!
//! The spec carries everything the episode needs: scene, plan, seed and the place targets (where
//! each placed object must end up). A worker therefore reads no dataset file, and a worker
//! machine never holds the test split's ground truth on disk; a spec whose place targets do not
//! match its plan's `place` steps is refused as a platform fault, never scored.
use std::time::Duration;

use kitchen_r_contract::RemoteConfig;
use kitchen_r_core::dataset::Instruction;
use kitchen_r_core::plan::place_steps;
use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams, SimConfig};

use super::JobError;
use kitchen_r_episode::offline::OfflineOptions;
use kitchen_r_episode::policy::{ChunkTolerance, HORIZON};
use kitchen_r_episode::runner::RunOptions;
use kitchen_r_sim::seeds::instruction_seed;

/// The instruction a job's spec describes: its plan and place targets as the server sent them.
pub(crate) fn instruction(spec: &pb::EpisodeSpec) -> Result<Instruction, JobError> {
    let places = place_steps(&spec.plan);
    if spec.place_targets.len() != places {
        return Err(JobError::Spec(format!(
            "instruction {:?}: {} place steps but {} place targets in the job (the server and \
             the worker must speak the same worker protocol)",
            spec.instruction_id,
            places,
            spec.place_targets.len()
        )));
    }
    Ok(Instruction {
        id: spec.instruction_id.clone(),
        scene: spec.scene_id.clone(),
        instruction: String::new(),
        plan: spec.plan.clone(),
        template: String::new(),
        place_targets: spec.place_target_points(),
    })
}

/// The simulator configuration of the job's episode; `episode_id` names it towards the policy.
pub(crate) fn episode_config(
    spec: &pb::EpisodeSpec,
    assets: &Assets,
    params: &EpisodeParams,
    episode_id: &str,
) -> Result<EpisodeConfig, JobError> {
    let ins = instruction(spec)?;
    let scene = assets
        .scene(&ins.scene)
        .map_err(|e| JobError::Spec(format!("scene {:?}: {e}", ins.scene)))?;
    let seed = instruction_seed(spec.seed, &ins.id);
    let mut cfg = EpisodeConfig::from_instruction(&ins, scene, &assets.catalogue, params, seed)
        .map_err(|e| JobError::Spec(format!("episode of {:?}: {e}", ins.id)))?;
    cfg.id = episode_id.to_string();
    Ok(cfg)
}

/// The worker's simulator configuration with the job's grasp mode: the organiser's contest
/// setting (server `[control] grasp`) overrides the worker's own `[grasp] mode` for its jobs. A
/// mode this build does not know is a platform fault, never run in another mode.
pub fn sim_config(spec: &pb::EpisodeSpec, base: &SimConfig) -> Result<SimConfig, JobError> {
    let mut cfg = base.clone();
    cfg.grasp.mode = spec.grasp().map_err(JobError::Spec)?;
    Ok(cfg)
}

/// A wire limit in milliseconds: proto3 sends 0 for a field the server left unset, which takes
/// the worker's default. Every millisecond field of a job is read through here, once.
fn limit_ms(ms: u32) -> Option<Duration> {
    (ms > 0).then(|| Duration::from_millis(u64::from(ms)))
}

/// The worker's transport limits with the job endpoint's deadlines; GetSpec announces the
/// privileged track when the run grants privileged observations (`privileged`).
pub(crate) fn remote_config(
    base: &RemoteConfig,
    ep: &pb::PolicyEndpoint,
    execute: usize,
    privileged: bool,
) -> RemoteConfig {
    let secs = |ms: u32, default: f64| limit_ms(ms).map_or(default, |d| d.as_secs_f64());
    RemoteConfig {
        call_deadline_s: secs(ep.call_deadline_ms, base.call_deadline_s),
        startup_deadline_s: secs(ep.startup_deadline_ms, base.startup_deadline_s),
        actions_executed_per_chunk: execute as u32,
        min_actions_executed_per_chunk: match ep.min_actions_executed_per_chunk {
            0 => base.min_actions_executed_per_chunk,
            n => n,
        },
        privileged_track: privileged,
        ..base.clone()
    }
}

/// The chunk check tolerances of the job; an absent one takes the worker's default.
fn chunk_tolerance(ep: &pb::PolicyEndpoint) -> Result<ChunkTolerance, JobError> {
    let d = ChunkTolerance::default();
    let tol = ChunkTolerance {
        quat_norm: ep.quat_norm_tolerance.unwrap_or(d.quat_norm),
        gripper_margin: ep.gripper_margin.unwrap_or(d.gripper_margin),
    };
    tol.validate().map_err(JobError::Spec)?;
    Ok(tol)
}

/// The runner's options for the job: the spec's settings, the endpoint's limits; a zero means
/// "not set" and takes the default.
pub(crate) fn run_options(spec: &pb::EpisodeSpec, ep: &pb::PolicyEndpoint) -> Result<RunOptions, JobError> {
    let d = RunOptions::default();
    let limit = spec.task_time_limit_s;
    if limit.is_nan() || limit < 0.0 {
        return Err(JobError::Spec(format!("task_time_limit_s {limit} is not >= 0")));
    }
    let execute = spec.actions_executed_per_chunk as usize;
    if execute > HORIZON {
        return Err(JobError::Spec(format!(
            "actions_executed_per_chunk {execute} exceeds the horizon {HORIZON}"
        )));
    }
    Ok(RunOptions {
        task_time_limit: if limit == 0.0 { d.task_time_limit } else { limit },
        execute: if execute == 0 { d.execute } else { execute },
        max_tasks: (spec.max_plan_steps > 0).then_some(spec.max_plan_steps as usize),
        privileged: spec.privileged,
        privileged_observations: spec.privileged_scope(),
        max_consecutive_timeouts: match ep.max_successive_timeouts {
            0 => d.max_consecutive_timeouts,
            n => n,
        },
        wall_budget: limit_ms(ep.episode_budget_ms),
        chunk_tolerance: chunk_tolerance(ep)?,
        budget_abort_at: None,
    })
}

/// Offline options for the job: the online ones plus the worker's sampling period.
pub(crate) fn offline_options(run: &RunOptions, sample_every: usize) -> OfflineOptions {
    OfflineOptions {
        sample_every: sample_every.max(1),
        ..OfflineOptions::from_run(run)
    }
}
