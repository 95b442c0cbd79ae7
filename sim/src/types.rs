//! The gym-style API's value types: action, observation, step info.

use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::sensors::{CameraImage, PointCloud};
use crate::task::{MonitorTrip, TaskStatus};

/// One action of the paper's PROBLEM FORMULATION: `(v, ω, x, y, z, qw, qx, qy, qz, g)`.
///
/// `v` (m/s) and `ω` (rad/s, CCW) command the base; `(x, y, z)` and the unit quaternion
/// `(qw, qx, qy, qz)` are the TCP target pose in the robot base frame; `g` is the gripper command,
/// 0 closed, 1 open. One action is applied for one control step (0.1 s by default).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Action(pub [f64; 10]);

impl Action {
    pub fn new(v: f64, omega: f64, pos: [f64; 3], quat_wxyz: [f64; 4], g: f64) -> Action {
        let [x, y, z] = pos;
        let [qw, qx, qy, qz] = quat_wxyz;
        Action([v, omega, x, y, z, qw, qx, qy, qz, g])
    }

    pub fn v(&self) -> f64 {
        self.0[0]
    }
    pub fn omega(&self) -> f64 {
        self.0[1]
    }
    pub fn position(&self) -> [f64; 3] {
        [self.0[2], self.0[3], self.0[4]]
    }
    /// `(qw, qx, qy, qz)`.
    pub fn quaternion(&self) -> [f64; 4] {
        [self.0[5], self.0[6], self.0[7], self.0[8]]
    }
    pub fn gripper(&self) -> f64 {
        self.0[9]
    }

    /// Finite values, a non-degenerate quaternion and g in [0, 1].
    pub fn validate(&self) -> Result<(), SimError> {
        if let Some(i) = self.0.iter().position(|v| !v.is_finite()) {
            return Err(SimError::BadAction(format!("value {i} is not finite")));
        }
        let n: f64 = self.quaternion().iter().map(|v| v * v).sum::<f64>().sqrt();
        if n < 1e-6 {
            return Err(SimError::BadAction("quaternion has zero length".into()));
        }
        if !(0.0..=1.0).contains(&self.gripper()) {
            return Err(SimError::BadAction(format!(
                "gripper {} outside [0, 1]",
                self.gripper()
            )));
        }
        Ok(())
    }
}

impl From<[f64; 10]> for Action {
    fn from(v: [f64; 10]) -> Self {
        Action(v)
    }
}

/// Base pose relative to where the episode started, and measured velocities.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// `[x, y, yaw]` in the start frame.
    pub pose: [f64; 3],
    /// `[v, ω]`.
    pub velocity: [f64; 2],
}

/// What a policy sees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Observation {
    pub time: f64,
    /// One per configured camera, in config order.
    pub images: Vec<CameraImage>,
    pub lidar: Option<PointCloud>,
    pub odometry: Odometry,
    /// Arm joint positions (rad).
    pub joints: [f64; 6],
    /// Finger gap in [0, 1] of the maximum.
    pub gripper: f64,
    /// The current sub-task sentence, if a task is running.
    pub task: Option<String>,
}

/// A robot part touching something.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Contact {
    pub robot_part: String,
    /// `scene` (walls, floor, furniture), a key object's name, or `background:<model>`.
    pub other: String,
    /// Penetration depth (m, ≥ 0 when touching).
    pub depth: f64,
}

/// Everything that happened in one control step, including privileged state.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepInfo {
    /// Sim time after the step (s).
    pub time: f64,
    /// Control steps since reset.
    pub step: u64,
    /// World `[x, y, yaw]` of the base centre.
    pub base_pose: [f64; 3],
    /// Measured `[v, ω]`.
    pub base_velocity: [f64; 2],
    /// TCP pose in the base frame `[x, y, z, qw, qx, qy, qz]`.
    pub ee_pose: [f64; 7],
    /// TCP pose in the world frame.
    pub ee_world: [f64; 7],
    pub joints: [f64; 6],
    pub gripper: f64,
    pub held_object: Option<String>,
    /// Every contact of a robot part with the scene or an object.
    pub contacts: Vec<Contact>,
    /// The arm was held back by fixed geometry during this step.
    pub arm_blocked: bool,
    pub task: Option<TaskStatus>,
    /// Episode-wide monitors that tripped (key object on the floor).
    pub monitors: Vec<MonitorTrip>,
}
