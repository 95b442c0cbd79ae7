//! Wire ↔ domain conversions, in one place: the worker protocol's task results and evaluation
//! mode against `kitchen_r_core::scoring`, and the grasp mode against `kitchen_r_core::GraspMode`.

use kitchen_r_core::GraspMode;
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
}
