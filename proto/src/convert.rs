//! Wire ↔ domain conversions, in one place: the worker protocol's task results and evaluation
//! mode against `kitchen_r_core::scoring`, and the grasp mode against `kitchen_r_core::GraspMode`.

use kitchen_r_core::GraspMode;
use kitchen_r_core::observations::PrivilegedScope;
use kitchen_r_core::scoring::{Mode, TaskOutcome};

use crate::worker::v1 as pb;

impl From<&pb::TaskResult> for TaskOutcome {
    /// A report is untrusted input: a non-finite or negative MSE would poison a run's mean, so it
    /// is dropped with its samples, and a non-finite time becomes 0.
    fn from(t: &pb::TaskResult) -> Self {
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

impl From<&TaskOutcome> for pb::TaskResult {
    fn from(t: &TaskOutcome) -> Self {
        pb::TaskResult {
            index: t.index,
            step: t.step.clone(),
            success: t.success,
            completion_time_s: t.completion_time_s,
            failure_reason: t.failure_reason.clone(),
            mse: t.mse,
            mse_samples: t.mse_samples,
            ..Default::default()
        }
    }
}

impl From<Mode> for pb::EvalMode {
    fn from(m: Mode) -> Self {
        match m {
            Mode::Online => pb::EvalMode::Online,
            Mode::Offline => pb::EvalMode::Offline,
        }
    }
}

impl pb::EvalMode {
    /// The domain mode; `None` for `EVAL_MODE_UNSPECIFIED`.
    pub fn mode(self) -> Option<Mode> {
        match self {
            pb::EvalMode::Online => Some(Mode::Online),
            pb::EvalMode::Offline => Some(Mode::Offline),
            pb::EvalMode::Unspecified => None,
        }
    }
}

impl From<GraspMode> for pb::GraspMode {
    fn from(m: GraspMode) -> Self {
        match m {
            GraspMode::Abstract => pb::GraspMode::Abstract,
            GraspMode::Physical => pb::GraspMode::Physical,
        }
    }
}

impl From<pb::GraspMode> for GraspMode {
    fn from(m: pb::GraspMode) -> Self {
        match m {
            pb::GraspMode::Abstract => GraspMode::Abstract,
            pb::GraspMode::Physical => GraspMode::Physical,
        }
    }
}

impl pb::EpisodeSpec {
    /// The episode's grasp mode; an absent field (an older server) is abstract, a value this
    /// build does not know is `Err` with it: running such an episode in another mode would score
    /// it under rules it was not asked for.
    pub fn grasp(&self) -> Result<GraspMode, String> {
        pb::GraspMode::try_from(self.grasp_mode)
            .map(GraspMode::from)
            .map_err(|_| {
                format!(
                    "unknown grasp mode {} in the job (a newer server?)",
                    self.grasp_mode
                )
            })
    }
}

/// How an episode is run and scored, besides which episode it is: what the server stores with a
/// job and what local `eval` sets, made into an [`pb::EpisodeSpec`] here only.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeRules {
    pub seed: u64,
    pub mode: Mode,
    pub task_time_limit_s: f64,
    pub actions_executed_per_chunk: u32,
    pub teleport_on_failure: bool,
    /// 0 = every plan step.
    pub max_plan_steps: u32,
    /// Organiser reference run: the policy gets privileged state.
    pub privileged: bool,
    /// The privileged track's observations; `None` on the standard track.
    pub privileged_observations: Option<PrivilegedScope>,
    pub grasp: GraspMode,
}

impl From<Option<PrivilegedScope>> for pb::PrivilegedScope {
    fn from(s: Option<PrivilegedScope>) -> Self {
        match s {
            None => pb::PrivilegedScope::None,
            Some(PrivilegedScope::Episode) => pb::PrivilegedScope::Episode,
            Some(PrivilegedScope::SubTask) => pb::PrivilegedScope::SubTask,
        }
    }
}

impl From<&[f64; 3]> for pb::PlaceTarget {
    fn from(t: &[f64; 3]) -> Self {
        pb::PlaceTarget {
            x: t[0],
            y: t[1],
            z: t[2],
        }
    }
}

impl pb::EpisodeSpec {
    /// The episode of instruction `instruction_id` (its scene, plan and place targets) run
    /// under `rules`. What a lease adds (the name the policy sees, video, the live view) is
    /// left unset for the caller.
    pub fn build(
        scene_id: &str,
        instruction_id: &str,
        plan: &[String],
        place_targets: &[[f64; 3]],
        rules: &EpisodeRules,
    ) -> pb::EpisodeSpec {
        pb::EpisodeSpec {
            scene_id: scene_id.to_string(),
            instruction_id: instruction_id.to_string(),
            plan: plan.to_vec(),
            seed: rules.seed,
            mode: pb::EvalMode::from(rules.mode) as i32,
            task_time_limit_s: rules.task_time_limit_s,
            actions_executed_per_chunk: rules.actions_executed_per_chunk,
            teleport_on_failure: rules.teleport_on_failure,
            max_plan_steps: rules.max_plan_steps,
            privileged: rules.privileged,
            place_targets: place_targets.iter().map(pb::PlaceTarget::from).collect(),
            privileged_observations: pb::PrivilegedScope::from(rules.privileged_observations) as i32,
            grasp_mode: pb::GraspMode::from(rules.grasp) as i32,
            policy_episode_id: String::new(),
            record_video: false,
            video_on_demand: false,
            video_max_bytes: 0,
            live_ros2: false,
        }
    }

    /// The privileged observations the job grants its policy; `None` on the standard track. The
    /// server chose the scope from the split; a value this build does not know grants nothing.
    pub fn privileged_scope(&self) -> Option<PrivilegedScope> {
        match pb::PrivilegedScope::try_from(self.privileged_observations) {
            Ok(pb::PrivilegedScope::Episode) => Some(PrivilegedScope::Episode),
            Ok(pb::PrivilegedScope::SubTask) => Some(PrivilegedScope::SubTask),
            Ok(pb::PrivilegedScope::None) | Err(_) => None,
        }
    }

    /// The place targets as world `[x, y, z]`, in plan order.
    pub fn place_target_points(&self) -> Vec<[f64; 3]> {
        self.place_targets.iter().map(|t| [t.x, t.y, t.z]).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_mse_from_a_worker_is_dropped_with_its_samples() {
        let t = pb::TaskResult {
            mse: f64::NAN,
            mse_samples: 3,
            completion_time_s: f64::INFINITY,
            ..Default::default()
        };
        let o = TaskOutcome::from(&t);
        assert_eq!((o.mse, o.mse_samples, o.completion_time_s), (0.0, 0, 0.0));
        let back = pb::TaskResult::from(&TaskOutcome {
            mse: 0.5,
            mse_samples: 2,
            ..Default::default()
        });
        assert_eq!(TaskOutcome::from(&back).mse_samples, 2);
    }

    #[test]
    fn modes_round_trip() {
        for m in [Mode::Online, Mode::Offline] {
            assert_eq!(pb::EvalMode::from(m).mode(), Some(m));
        }
        assert_eq!(pb::EvalMode::Unspecified.mode(), None);
    }

    #[test]
    fn grasp_modes_round_trip_and_an_old_spec_is_abstract() {
        for m in GraspMode::ALL {
            let spec = pb::EpisodeSpec {
                grasp_mode: pb::GraspMode::from(m) as i32,
                ..Default::default()
            };
            assert_eq!(spec.grasp(), Ok(m));
        }
        assert_eq!(pb::EpisodeSpec::default().grasp(), Ok(GraspMode::Abstract));
        let future = pb::EpisodeSpec {
            grasp_mode: 7,
            ..Default::default()
        };
        assert!(future.grasp().unwrap_err().contains("unknown grasp mode 7"));
    }

    #[test]
    fn a_built_spec_carries_its_rules_and_targets_back() {
        for scope in [
            None,
            Some(PrivilegedScope::Episode),
            Some(PrivilegedScope::SubTask),
        ] {
            let rules = EpisodeRules {
                seed: 7,
                mode: Mode::Offline,
                task_time_limit_s: 60.0,
                actions_executed_per_chunk: 8,
                teleport_on_failure: true,
                max_plan_steps: 2,
                privileged: false,
                privileged_observations: scope,
                grasp: GraspMode::Abstract,
            };
            let plan = vec!["pick the apple".to_string()];
            let spec = pb::EpisodeSpec::build("s1", "dev-0001", &plan, &[[1.0, 2.0, 3.0]], &rules);
            assert_eq!(spec.privileged_scope(), scope);
            assert_eq!(spec.place_target_points(), vec![[1.0, 2.0, 3.0]]);
            assert_eq!(
                (spec.seed, spec.mode().mode(), spec.grasp()),
                (7, Some(Mode::Offline), Ok(GraspMode::Abstract))
            );
        }
        let unknown = pb::EpisodeSpec {
            privileged_observations: 9,
            ..Default::default()
        };
        assert_eq!(unknown.privileged_scope(), None);
    }
}
