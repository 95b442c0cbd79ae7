//! A leased job's `EpisodeSpec` as the simulator's episode configuration and the runner's
//! options, derived exactly as `kitchen-r eval` derives them (the episode seed is
//! [`instruction_seed`] of the run seed and the instruction id), so a participant's local number
//! and the leaderboard's are the same number.
//!
//! The spec carries the plan but not the place targets (where each placed object must end up),
//! which are part of the dataset's ground truth: the worker looks the instruction up in its own
//! copy of the dataset and refuses a job whose scene or plan disagree with it, since scoring a
//! different episode than the server asked for would be silent corruption.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Duration;

use kitchen_r_core::dataset::{Instruction, read_jsonl};
use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_sim::{Assets, EpisodeConfig, EpisodeParams};

use super::JobError;
use crate::eval::instruction_seed;
use crate::offline::OfflineOptions;
use crate::policy::HORIZON;
use crate::runner::RunOptions;

/// The ground-truth instructions a worker can simulate, by id.
#[derive(Debug, Clone, Default)]
pub struct Instructions {
    by_id: HashMap<String, Instruction>,
}

impl Instructions {
    /// `dev.jsonl` and, when present, `test_ground_truth.jsonl` of the assets' `dataset/`.
    pub fn default_files() -> Vec<PathBuf> {
        Instructions::files_in(&kitchen_r_core::assets::assets_dir())
    }

    /// The ground-truth files of the assets directory `assets` (those that exist).
    pub fn files_in(assets: &std::path::Path) -> Vec<PathBuf> {
        let dir = assets.join("dataset");
        ["dev.jsonl", "test_ground_truth.jsonl"]
            .into_iter()
            .map(|f| dir.join(f))
            .filter(|p| p.is_file())
            .collect()
    }

    /// Every instruction of the given JSON Lines files; a later file wins on a repeated id.
    pub fn load(files: &[PathBuf]) -> Result<Instructions, JobError> {
        let mut by_id = HashMap::new();
        for f in files {
            let list: Vec<Instruction> =
                read_jsonl(f).map_err(|e| JobError::Setup(format!("dataset {}: {e}", f.display())))?;
            by_id.extend(list.into_iter().map(|i| (i.id.clone(), i)));
        }
        Ok(Instructions { by_id })
    }

    pub fn from_list(list: impl IntoIterator<Item = Instruction>) -> Instructions {
        Instructions {
            by_id: list.into_iter().map(|i| (i.id.clone(), i)).collect(),
        }
    }

    pub fn len(&self) -> usize {
        self.by_id.len()
    }

    pub fn is_empty(&self) -> bool {
        self.by_id.is_empty()
    }

    /// The instruction the spec names, checked against it.
    pub fn resolve(&self, spec: &pb::EpisodeSpec) -> Result<Instruction, JobError> {
        let id = &spec.instruction_id;
        let Some(ins) = self.by_id.get(id) else {
            // Without place steps nothing is missing from the spec itself.
            if spec.plan.iter().all(|s| !s.starts_with("place ")) {
                return Ok(Instruction {
                    id: id.clone(),
                    scene: spec.scene_id.clone(),
                    instruction: String::new(),
                    plan: spec.plan.clone(),
                    template: String::new(),
                    place_targets: Vec::new(),
                });
            }
            return Err(JobError::Spec(format!(
                "instruction {id:?} is not in this worker's dataset ({} instructions), and its \
                 place targets are needed: give the worker the dataset file (`datasets` key)",
                self.by_id.len()
            )));
        };
        if ins.scene != spec.scene_id || ins.plan != spec.plan {
            return Err(JobError::Spec(format!(
                "instruction {id:?} differs between the job (scene {:?}, {} steps) and this \
                 worker's dataset (scene {:?}, {} steps): the server and the worker must use the \
                 same dataset",
                spec.scene_id,
                spec.plan.len(),
                ins.scene,
                ins.plan.len()
            )));
        }
        Ok(ins.clone())
    }
}

/// The simulator configuration of the job's episode; `episode_id` names it towards the policy.
pub fn episode_config(
    spec: &pb::EpisodeSpec,
    assets: &Assets,
    params: &EpisodeParams,
    instructions: &Instructions,
    episode_id: &str,
) -> Result<EpisodeConfig, JobError> {
    let ins = instructions.resolve(spec)?;
    let scene = assets
        .scene(&ins.scene)
        .map_err(|e| JobError::Spec(format!("scene {:?}: {e}", ins.scene)))?;
    let seed = instruction_seed(spec.seed, &ins.id);
    let mut cfg = EpisodeConfig::from_instruction(&ins, scene, &assets.catalogue, params, seed)
        .map_err(|e| JobError::Spec(format!("episode of {:?}: {e}", ins.id)))?;
    cfg.id = episode_id.to_string();
    Ok(cfg)
}

/// The runner's options for the job: the spec's settings, the endpoint's limits; a zero means
/// "not set" and takes the default.
pub fn run_options(spec: &pb::EpisodeSpec, ep: &pb::PolicyEndpoint) -> Result<RunOptions, JobError> {
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
        max_consecutive_timeouts: match ep.max_successive_timeouts {
            0 => d.max_consecutive_timeouts,
            n => n,
        },
        wall_budget: (ep.episode_budget_ms > 0)
            .then(|| Duration::from_millis(u64::from(ep.episode_budget_ms))),
    })
}

/// Offline options for the job: the online ones plus the worker's sampling period.
pub fn offline_options(run: &RunOptions, sample_every: usize) -> OfflineOptions {
    OfflineOptions {
        sample_every: sample_every.max(1),
        ..OfflineOptions::from_run(run)
    }
}
