//! Plan steps as tasks: their targets, success checks (paper, METRICS) and the Monitoring
//! Module's checks (time limits, key object on the floor, gripper-to-object distance after a
//! pick, object-to-goal distance after a place, robot inside the goal circle after a move).

use kitchen_r_core::plan::Step;
use kitchen_r_core::scene::Scene;
use serde::{Deserialize, Serialize};

use crate::config::{MonitorConfig, SuccessConfig};
use crate::episode::EpisodeConfig;
use crate::error::SimError;

/// What a plan step must achieve, in world coordinates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum TaskTarget {
    /// Bring the base centre to `[x, y]` (the zone's approach point); `yaw` is the approach heading.
    Base { x: f64, y: f64, yaw: f64 },
    /// Grasp key object `object` (index into the episode's objects) and lift it.
    Pick { object: usize },
    /// Put key object `object` down with its centre at `target`.
    Place { object: usize, target: [f64; 3] },
}

/// Resolve plan step `index` of `episode` to its target: the zone approach point for a move, the
/// object for a pick, the episode's next place target for a place.
pub fn task_target(episode: &EpisodeConfig, scene: &Scene, index: usize) -> Result<TaskTarget, SimError> {
    let text = episode
        .plan
        .get(index)
        .ok_or_else(|| SimError::Episode(format!("plan has no step {index}")))?;
    let step: Step = text.parse()?;
    let object = |name: &str| {
        episode
            .objects
            .iter()
            .position(|o| o.name == name)
            .ok_or_else(|| SimError::Episode(format!("no object {name:?} in the episode")))
    };
    match &step {
        Step::MoveTo { zone } => {
            let z = scene
                .zone(zone)
                .ok_or_else(|| SimError::Episode(format!("no zone {zone:?}")))?;
            Ok(TaskTarget::Base {
                x: z.approach[0],
                y: z.approach[1],
                yaw: z.approach[2],
            })
        }
        Step::Pick { object: name } => Ok(TaskTarget::Pick {
            object: object(name)?,
        }),
        Step::Place { object: name } => {
            let nth = kitchen_r_core::plan::place_steps(&episode.plan[..index]);
            let target = *episode
                .place_targets
                .get(nth)
                .ok_or_else(|| SimError::Episode(format!("no place target for step {index}")))?;
            Ok(TaskTarget::Place {
                object: object(name)?,
                target,
            })
        }
    }
}

/// Why a task or episode was flagged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "monitor", rename_all = "snake_case")]
pub enum MonitorTrip {
    TimeLimit { limit: f64 },
    ObjectOnFloor { object: String },
    GripperFarFromObject { distance: f64 },
    ObjectFarFromGoal { distance: f64 },
    RobotOutsideGoal { distance: f64 },
}

/// The world facts a task check needs, gathered by the simulator each control step.
#[derive(Debug, Clone)]
pub struct Facts {
    pub time: f64,
    pub base_xy: [f64; 2],
    /// Centre of each key object.
    pub objects: Vec<[f64; 3]>,
    /// Bottom height of each key object above the floor.
    pub bottoms: Vec<f64>,
    pub held: Option<usize>,
    /// Distance from the TCP to each object's grasp point.
    pub tcp_to_grasp: Vec<f64>,
}

/// A running task.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Task {
    pub index: usize,
    pub step: String,
    pub target: TaskTarget,
    pub started: f64,
    /// Height of the surface a picked object stood on when the task began.
    pub support: f64,
    pub succeeded_at: Option<f64>,
}

/// The state of the current task after a control step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskStatus {
    pub index: usize,
    pub step: String,
    pub elapsed: f64,
    pub success: bool,
    /// A monitor that failed the task, if any.
    pub failure: Option<MonitorTrip>,
}

fn dist2(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn dist3(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

impl Task {
    pub fn new(index: usize, step: String, target: TaskTarget, facts: &Facts) -> Task {
        let support = match target {
            TaskTarget::Pick { object } => facts.bottoms.get(object).copied().unwrap_or(0.0),
            _ => 0.0,
        };
        Task {
            index,
            step,
            target,
            started: facts.time,
            support,
            succeeded_at: None,
        }
    }

    /// Success criterion of the paper's METRICS, checked after every action.
    pub fn achieved(&self, s: &SuccessConfig, f: &Facts) -> bool {
        match self.target {
            TaskTarget::Base { x, y, .. } => dist2(f.base_xy, [x, y]) <= s.navigation_tolerance,
            TaskTarget::Pick { object } => {
                f.held == Some(object) && f.bottoms[object] >= self.support + s.lift_clearance
            }
            TaskTarget::Place { object, target } => {
                f.held != Some(object) && dist3(f.objects[object], target) <= s.manipulation_tolerance
            }
        }
    }

    /// Update after a control step: success, time limit.
    pub fn update(&mut self, s: &SuccessConfig, m: &MonitorConfig, f: &Facts) -> TaskStatus {
        if self.succeeded_at.is_none() && self.achieved(s, f) {
            self.succeeded_at = Some(f.time);
        }
        let elapsed = f.time - self.started;
        let limit = match self.target {
            TaskTarget::Base { .. } => m.move_time_limit,
            TaskTarget::Pick { .. } => m.pick_time_limit,
            TaskTarget::Place { .. } => m.place_time_limit,
        };
        let failure =
            (self.succeeded_at.is_none() && elapsed > limit).then_some(MonitorTrip::TimeLimit { limit });
        TaskStatus {
            index: self.index,
            step: self.step.clone(),
            elapsed,
            success: self.succeeded_at.is_some(),
            failure,
        }
    }

    /// How far the task is from its success criterion, in words, for a failure reason (a
    /// participant sees *why* a task failed: "never moved" and "stopped 12 cm short" call for
    /// different fixes). `name` gives key object `i`'s name.
    pub fn shortfall(&self, s: &SuccessConfig, f: &Facts, name: &dyn Fn(usize) -> String) -> String {
        match self.target {
            TaskTarget::Base { x, y, .. } => format!(
                "the base centre ended {:.2} m from the zone's approach point (success within {:.2} m)",
                dist2(f.base_xy, [x, y]),
                s.navigation_tolerance
            ),
            TaskTarget::Pick { object } if f.held == Some(object) => format!(
                "the {} was grasped but lifted {:.1} cm (success from {:.1} cm)",
                name(object),
                100.0 * (f.bottoms[object] - self.support).max(0.0),
                100.0 * s.lift_clearance
            ),
            TaskTarget::Pick { object } => format!(
                "the {} was not grasped; the gripper ended {:.2} m from its grasp point",
                name(object),
                f.tcp_to_grasp[object]
            ),
            TaskTarget::Place { object, target } => {
                let d = dist3(f.objects[object], target);
                if f.held == Some(object) {
                    format!("the {} was still held, {d:.2} m from its target", name(object))
                } else {
                    format!(
                        "the {} ended {d:.2} m from its target (success within {:.2} m)",
                        name(object),
                        s.manipulation_tolerance
                    )
                }
            }
        }
    }

    /// Monitors evaluated when the task ends (paper, Monitoring Module).
    pub fn end_checks(&self, m: &MonitorConfig, f: &Facts) -> Option<MonitorTrip> {
        match self.target {
            TaskTarget::Base { x, y, .. } => {
                let d = dist2(f.base_xy, [x, y]);
                (d > m.move_goal_radius).then_some(MonitorTrip::RobotOutsideGoal { distance: d })
            }
            TaskTarget::Pick { object } => {
                let d = f.tcp_to_grasp[object];
                (d > m.pick_gripper_distance).then_some(MonitorTrip::GripperFarFromObject { distance: d })
            }
            TaskTarget::Place { object, target } => {
                let d = dist3(f.objects[object], target);
                (d > m.place_goal_distance).then_some(MonitorTrip::ObjectFarFromGoal { distance: d })
            }
        }
    }
}

/// Key objects whose centre is below the floor threshold (the episode-wide monitor).
pub fn objects_on_floor(m: &MonitorConfig, f: &Facts, names: &[String]) -> Vec<MonitorTrip> {
    f.objects
        .iter()
        .zip(names)
        .filter(|(p, _)| p[2] < m.floor_height)
        .map(|(_, n)| MonitorTrip::ObjectOnFloor { object: n.clone() })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn facts(base: [f64; 2], object: [f64; 3], held: Option<usize>) -> Facts {
        Facts {
            time: 0.0,
            base_xy: base,
            objects: vec![object],
            bottoms: vec![object[2] - 0.05],
            held,
            tcp_to_grasp: vec![0.25],
        }
    }

    fn task(target: TaskTarget, f: &Facts) -> Task {
        Task::new(0, "step".into(), target, f)
    }

    fn name(_: usize) -> String {
        "red cup".into()
    }

    #[test]
    fn a_failed_move_says_how_far_the_base_ended_from_the_approach_point() {
        let f = facts([1.0, 1.0], [0.0; 3], None);
        let t = task(
            TaskTarget::Base {
                x: 1.3,
                y: 1.4,
                yaw: 0.0,
            },
            &f,
        );
        assert_eq!(
            t.shortfall(&SuccessConfig::default(), &f, &name),
            "the base centre ended 0.50 m from the zone's approach point (success within 0.10 m)"
        );
    }

    #[test]
    fn a_failed_pick_says_whether_the_object_was_grasped_and_how_far_it_was_lifted() {
        let start = facts([0.0; 2], [2.0, 0.0, 0.90], None);
        let t = task(TaskTarget::Pick { object: 0 }, &start);
        let s = SuccessConfig::default();
        assert_eq!(
            t.shortfall(&s, &start, &name),
            "the red cup was not grasped; the gripper ended 0.25 m from its grasp point"
        );
        let lifted = facts([0.0; 2], [2.0, 0.0, 0.91], Some(0));
        assert_eq!(
            t.shortfall(&s, &lifted, &name),
            "the red cup was grasped but lifted 1.0 cm (success from 3.0 cm)"
        );
    }

    #[test]
    fn a_failed_place_says_how_far_the_object_is_from_its_target() {
        let target = [1.0, 1.0, 0.8];
        let f = facts([0.0; 2], [1.0, 1.2, 0.8], None);
        let t = task(TaskTarget::Place { object: 0, target }, &f);
        let s = SuccessConfig::default();
        assert_eq!(
            t.shortfall(&s, &f, &name),
            "the red cup ended 0.20 m from its target (success within 0.05 m)"
        );
        let held = facts([0.0; 2], [1.0, 1.2, 0.8], Some(0));
        assert_eq!(
            t.shortfall(&s, &held, &name),
            "the red cup was still held, 0.20 m from its target"
        );
    }
}
