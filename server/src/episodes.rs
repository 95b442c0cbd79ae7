//! Episodes of a policy run as the server handles them: what a job asks a worker to simulate
//! ([`JobSpec`], stored as JSON in `jobs.spec`) and a recorded episode with the spec it ran
//! under ([`Episode`]). Scoring itself (modes, task outcomes, aggregation) is
//! `kitchen_r_core::scoring`, shared with the workers and local `eval`; [`aggregate`] only hands
//! the recorded episodes to it.

use std::collections::HashMap;

use kitchen_r_core::GraspMode;
use kitchen_r_core::observations::PrivilegedScope;
use kitchen_r_core::scoring;
use kitchen_r_proto::convert::EpisodeRules;
use kitchen_r_proto::worker::v1 as pb;
use serde::{Deserialize, Serialize};

pub(crate) use kitchen_r_core::scoring::{Mode, RunScores, TaskOutcome};

/// Where the policy is, the deadlines to call it with and the contract's limits (snapshotted
/// at registration). The limits added with contract v1.1 are absent from specs stored before
/// it: they then take the worker's defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct EndpointSpec {
    pub url: String,
    /// The plain token, empty for none. Always empty as stored: set from `bearer_token_sealed`
    /// when the job is leased (specs stored before tokens were sealed are sealed at start-up).
    #[serde(default)]
    pub bearer_token: String,
    /// The token sealed with the server's key (`crate::secrets`); absent for none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bearer_token_sealed: Option<String>,
    pub call_deadline_ms: u32,
    pub startup_deadline_ms: u32,
    pub episode_budget_ms: u32,
    pub max_successive_timeouts: u32,
    /// `control.min_actions_executed_per_chunk`; 0 = the worker's default.
    #[serde(default)]
    pub min_actions_executed_per_chunk: u32,
    /// `policy.quat_norm_tolerance` and `policy.gripper_margin`.
    #[serde(default)]
    pub quat_norm_tolerance: Option<f64>,
    #[serde(default)]
    pub gripper_margin: Option<f64>,
    /// An openpi (`ws://`) endpoint's key map as checked at registration (JSON); absent for
    /// gRPC endpoints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub key_map: Option<String>,
}

/// One job: an episode to simulate and the policy to drive it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct JobSpec {
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
    /// The privileged track: the scope of the privileged observations the policy gets; absent
    /// for standard runs (and in every spec stored before the track existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub privileged_observations: Option<PrivilegedScope>,
    pub endpoint: EndpointSpec,
    /// World `[x, y, z]` of each `place` step's target, in plan order: the job carries its whole
    /// episode so workers hold no dataset. Empty in specs stored before it was added (filled in
    /// from the content at lease time).
    #[serde(default)]
    pub place_targets: Vec<[f64; 3]>,
    /// The grasp mode the episode runs in (`control.grasp` when the run was queued); absent in
    /// specs stored before it existed, which ran the abstract grasp.
    #[serde(default)]
    pub grasp: GraspMode,
}

impl JobSpec {
    /// Tasks the episode has: the plan's steps, capped by `max_plan_steps` (0 = no cap).
    pub(crate) fn task_count(&self) -> usize {
        scoring::task_count(self.plan.len(), self.max_plan_steps)
    }

    /// The episode as a worker gets it; `policy_episode_id` is the opaque name the endpoint sees.
    pub(crate) fn episode_proto(&self, policy_episode_id: &str) -> pb::EpisodeSpec {
        let rules = EpisodeRules {
            seed: self.seed,
            mode: self.mode,
            task_time_limit_s: self.task_time_limit_s,
            actions_executed_per_chunk: self.actions_executed_per_chunk,
            teleport_on_failure: self.teleport_on_failure,
            max_plan_steps: self.max_plan_steps,
            privileged: self.privileged,
            privileged_observations: self.privileged_observations,
            grasp: self.grasp,
        };
        // Video and the live view are set at lease (`grpc_worker`), not stored with the job.
        pb::EpisodeSpec {
            policy_episode_id: policy_episode_id.to_string(),
            ..pb::EpisodeSpec::build(
                &self.scene_id,
                &self.instruction_id,
                &self.plan,
                &self.place_targets,
                &rules,
            )
        }
    }

    pub(crate) fn endpoint_proto(&self) -> pb::PolicyEndpoint {
        let e = &self.endpoint;
        pb::PolicyEndpoint {
            url: e.url.clone(),
            bearer_token: e.bearer_token.clone(),
            call_deadline_ms: e.call_deadline_ms,
            startup_deadline_ms: e.startup_deadline_ms,
            episode_budget_ms: e.episode_budget_ms,
            max_successive_timeouts: e.max_successive_timeouts,
            min_actions_executed_per_chunk: e.min_actions_executed_per_chunk,
            quat_norm_tolerance: e.quat_norm_tolerance,
            gripper_margin: e.gripper_margin,
            key_map: e.key_map.clone().unwrap_or_default(),
        }
    }
}

/// A recorded episode: its spec and what happened.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Episode {
    pub spec: JobSpec,
    pub tasks: Vec<TaskOutcome>,
    /// Set when the episode never ran: the platform gave up after its attempts.
    pub failure: Option<String>,
}

impl Episode {
    /// The episode as scoring sees it.
    pub(crate) fn scoring(&self) -> scoring::Episode {
        scoring::Episode {
            mode: self.spec.mode,
            instruction_id: self.spec.instruction_id.clone(),
            plan: self.spec.plan.clone(),
            task_count: self.spec.task_count(),
            tasks: self.tasks.clone(),
            failure: self.failure.clone(),
        }
    }
}

/// Scores of a finished run ([`scoring::aggregate`]). `plans` are the linked plan submission's
/// predictions by instruction id (integrated runs only).
pub(crate) fn aggregate(episodes: &[Episode], plans: Option<&HashMap<String, Vec<String>>>) -> RunScores {
    let scored: Vec<scoring::Episode> = episodes.iter().map(Episode::scoring).collect();
    scoring::aggregate(&scored, plans)
}

#[cfg(test)]
mod tests;
