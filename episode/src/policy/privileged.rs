//! The privileged-information track: what a participant's policy that asked for privileged
//! observations (`PolicySpec::privileged_observations`) sees besides the standard observation,
//! derived from the reference runs' full world state ([`Privileged`]) by one pure function,
//! [`PrivilegedObservation::from_world`], so the runner, offline MSE episodes and every
//! transport show exactly the same thing.
//!
//! Policy (what each split shows; the same rule is written in `policy.proto` and docs/participant/privileged.md):
//! a privileged observation describes the current episode only, so it tells nothing about any
//! other instruction. It always carries the robot's pose in the scene frame and the current
//! task's goal in the robot (base) frame: the approach pose of the zone a `move to` names, the
//! pose of the object a `pick` names, the object a `place` names and the point its centre must
//! reach. Beyond that:
//! - [`PrivilegedScope::Episode`] (dev split, whose plans are public): every key object of the
//!   episode with its pose in the scene frame;
//! - [`PrivilegedScope::SubTask`] (test split): nothing beyond what the current sub-task already
//!   names, so `objects` holds only the object the sub-task names (none for a `move to`). The
//!   other key objects would tell which objects later steps of the hidden plan handle, and a
//!   later task's goal is never computed at all. When in doubt the test split shows less.

use kitchen_r_sim::task::TaskTarget;
use nalgebra::{Quaternion, UnitQuaternion};
use serde::{Deserialize, Serialize};

pub use kitchen_r_core::observations::PrivilegedScope;

use super::{Privileged, PrivilegedObject};

/// The current task's goal in the robot (base) frame: x forward, y left, z up, origin at the
/// base centre on the floor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Goal {
    /// `move to …`: the zone's approach point `[x, y]` and its heading relative to the base's,
    /// in (-π, π].
    Approach { x: f64, y: f64, yaw: f64 },
    /// `pick …`: the named object and its pose `[x, y, z, qw, qx, qy, qz]`.
    Pick { object: String, pose: [f64; 7] },
    /// `place …`: the named object and the point `[x, y, z]` its centre must reach.
    Place { object: String, target: [f64; 3] },
}

/// What a policy on the privileged track sees at one decision.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrivilegedObservation {
    /// Base centre in the scene frame `[x, y, yaw]`.
    pub base_pose: [f64; 3],
    pub goal: Goal,
    /// Key objects in the scene frame, as the scope allows (see the module documentation).
    pub objects: Vec<PrivilegedObject>,
}

impl PrivilegedObservation {
    /// What `scope` lets a policy see of the world state `p`. `None` when the state's target
    /// names an object the state does not list (a corrupt state; never shown half-filled).
    pub fn from_world(p: &Privileged, scope: PrivilegedScope) -> Option<PrivilegedObservation> {
        let frame = BaseFrame::new(p.base_pose);
        let (goal, named) = match &p.target {
            TaskTarget::Base { x, y, yaw } => {
                let [gx, gy, _] = frame.point([*x, *y, 0.0]);
                let yaw = wrap(yaw - p.base_pose[2]);
                (Goal::Approach { x: gx, y: gy, yaw }, None)
            }
            TaskTarget::Pick { object } => {
                let o = p.objects.get(*object)?;
                let pose = frame.pose(&o.pose);
                (
                    Goal::Pick {
                        object: o.name.clone(),
                        pose,
                    },
                    Some(o),
                )
            }
            TaskTarget::Place { object, target } => {
                let o = p.objects.get(*object)?;
                let target = frame.point(*target);
                (
                    Goal::Place {
                        object: o.name.clone(),
                        target,
                    },
                    Some(o),
                )
            }
        };
        let objects = match scope {
            PrivilegedScope::Episode => p.objects.clone(),
            PrivilegedScope::SubTask => named.cloned().into_iter().collect(),
        };
        Some(PrivilegedObservation {
            base_pose: p.base_pose,
            goal,
            objects,
        })
    }
}

/// The robot (base) frame at one instant: the base's pose in the scene frame.
struct BaseFrame {
    origin: [f64; 2],
    /// Rotation from the scene frame into the base frame (the inverse of the base's yaw).
    inverse: UnitQuaternion<f64>,
    cos: f64,
    sin: f64,
}

impl BaseFrame {
    fn new([x, y, yaw]: [f64; 3]) -> BaseFrame {
        BaseFrame {
            origin: [x, y],
            inverse: UnitQuaternion::from_euler_angles(0.0, 0.0, yaw).inverse(),
            cos: yaw.cos(),
            sin: yaw.sin(),
        }
    }

    /// A scene point in the base frame (the base frame's origin is on the floor, so z stays).
    fn point(&self, [x, y, z]: [f64; 3]) -> [f64; 3] {
        let (dx, dy) = (x - self.origin[0], y - self.origin[1]);
        [self.cos * dx + self.sin * dy, -self.sin * dx + self.cos * dy, z]
    }

    /// A scene pose `[x, y, z, qw, qx, qy, qz]` in the base frame.
    fn pose(&self, p: &[f64; 7]) -> [f64; 7] {
        let [x, y, z] = self.point([p[0], p[1], p[2]]);
        let q = self.inverse * UnitQuaternion::from_quaternion(Quaternion::new(p[3], p[4], p[5], p[6]));
        [x, y, z, q.w, q.i, q.j, q.k]
    }
}

/// An angle in (-π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI {
        w - std::f64::consts::TAU
    } else {
        w
    }
}

#[cfg(test)]
mod tests;
