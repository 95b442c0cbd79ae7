//! The robot description (`assets/robot.toml`): base footprint and limits, arm joints, gripper.
//! See the file's header for the frame conventions.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{SimError, read_toml};

/// The whole robot as described in `assets/robot.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotDesc {
    pub base: BaseDesc,
    pub arm: ArmDesc,
    pub gripper: GripperDesc,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BaseDesc {
    /// Navigation footprint radius around the base centre (m).
    pub radius: f64,
    pub body_radius: f64,
    pub height: f64,
    pub clearance: f64,
    pub mass: f64,
    pub max_v: f64,
    pub max_omega: f64,
    pub acc_v: f64,
    pub acc_omega: f64,
    pub column_center: [f64; 3],
    pub column_size: [f64; 3],
    pub color: [f32; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArmDesc {
    pub mount: [f64; 3],
    pub home: Vec<f64>,
    pub color: [f32; 3],
    #[serde(rename = "joint")]
    pub joints: Vec<JointDesc>,
}

/// A revolute joint about one axis of its (zero-configuration) frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointDesc {
    pub name: String,
    /// Offset from the previous joint's frame (or the mount) at zero configuration.
    pub origin: [f64; 3],
    pub axis: Axis,
    /// `[lower, upper]` in radians.
    pub limits: [f64; 2],
    /// rad/s.
    pub max_velocity: f64,
    /// Radius of the capsule from this joint to the next one (or to the palm).
    pub link_radius: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GripperDesc {
    pub tcp_offset: f64,
    pub palm_size: [f64; 3],
    pub palm_back: f64,
    pub finger_length: f64,
    pub finger_thickness: f64,
    pub finger_height: f64,
    pub max_opening: f64,
    pub opening_speed: f64,
    pub grasp_threshold: f64,
    pub release_threshold: f64,
    pub color: [f32; 3],
}

impl Axis {
    pub fn unit(self) -> nalgebra::Vector3<f64> {
        match self {
            Axis::X => nalgebra::Vector3::x(),
            Axis::Y => nalgebra::Vector3::y(),
            Axis::Z => nalgebra::Vector3::z(),
        }
    }
}

impl RobotDesc {
    /// Load and validate `path` (normally `assets/robot.toml`).
    pub fn load(path: &Path) -> Result<RobotDesc, SimError> {
        let desc: RobotDesc = read_toml(path)?;
        desc.validate()?;
        Ok(desc)
    }

    /// The committed robot from the assets directory.
    pub fn load_default() -> Result<RobotDesc, SimError> {
        RobotDesc::load(&kitchen_r_core::assets::assets_dir().join("robot.toml"))
    }

    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |m: String| Err(SimError::Config(format!("robot: {m}")));
        if self.arm.joints.len() != 6 {
            return bad(format!("the arm needs 6 joints, got {}", self.arm.joints.len()));
        }
        if self.arm.home.len() != self.arm.joints.len() {
            return bad("arm.home needs one value per joint".into());
        }
        for (j, h) in self.arm.joints.iter().zip(&self.arm.home) {
            if j.limits[0] >= j.limits[1] || *h < j.limits[0] || *h > j.limits[1] || j.max_velocity <= 0.0 {
                return bad(format!("joint {:?}: bad limits, home or speed", j.name));
            }
        }
        let b = &self.base;
        if [
            b.radius,
            b.body_radius,
            b.mass,
            b.max_v,
            b.max_omega,
            b.acc_v,
            b.acc_omega,
        ]
        .iter()
        .any(|v| *v <= 0.0)
        {
            return bad("base sizes, mass and limits must be positive".into());
        }
        let g = &self.gripper;
        if g.max_opening <= 0.0 || g.grasp_threshold >= g.release_threshold || g.release_threshold > 1.0 {
            return bad("gripper: need max_opening > 0 and grasp_threshold < release_threshold <= 1".into());
        }
        Ok(())
    }
}
