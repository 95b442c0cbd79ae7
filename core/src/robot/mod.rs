//! The robot description: base footprint and limits, the arm's six revolute joints, the gripper,
//! read from a URDF or MJCF file plus a small sidecar TOML beside it (docs/twin/robot.md, issue
//! #27).
//!
//! A description file is a tree of frames ([`tree::Tree`]); [`chain`] maps the serial chain from
//! the base frame to the tool frame onto [`RobotDesc`], which the twin's kinematics, spawner and
//! oracle read. The sidecar ([`sidecar::Sidecar`]) says what neither format can: which frames are
//! the base and the tool, the base's speed limits and navigation radius, the arm's home pose and
//! the gripper's thresholds.
//!
//! Frames: the robot base frame has its origin at the base's centre on the floor, x forward, y
//! left, z up. Each arm joint's frame is its parent's moved by `origin` and turned by `rotation`
//! (none for the shipped robot, whose joint frames are all parallel to the base frame at zero),
//! and the joint turns about `axis` of its own frame. The hand frame hangs from the last joint's
//! frame (by `flange`, none for the shipped robot); the tool frame (the tool centre point,
//! between the fingertips) lies `tcp_offset` along the hand frame's x axis: x = approach
//! direction, y = closing axis of the fingers.
//!
//! Two ways to describe a robot: one URDF or MJCF file with the twin's base, arm and hand in it
//! and its sidecar beside it ([`chain`]), or a sidecar that mounts an arm file and a gripper file
//! as the field ships them on the twin's base ([`mounted`], e.g. robosuite's arms).

mod chain;
mod frame;
mod mjcf;
mod mounted;
pub(crate) use mounted::resolve_file;
mod shapes;
pub mod sidecar;
mod tree;
mod urdf;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::ContentError;

/// The shipped robot, relative to the assets directory.
pub const SHIPPED: &str = "robots/kitchen_r_aloha.urdf";

/// The whole robot, as the twin uses it.
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
    /// Rotation of the first joint's parent frame against the base frame, `w, x, y, z` (`None`:
    /// parallel to it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mount_rotation: Option<[f64; 4]>,
    pub home: Vec<f64>,
    pub color: [f32; 3],
    #[serde(rename = "joint")]
    pub joints: Vec<JointDesc>,
    /// The hand frame in the last joint's frame (`None`: the last joint's frame itself).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flange: Option<PoseDesc>,
    /// Shapes fixed to the hand beyond the palm and fingers (a gripper file's meshes), in the
    /// last joint's frame.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub hand_shapes: Vec<LinkShape>,
}

/// A rigid transform: translation, then rotation `w, x, y, z`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseDesc {
    pub xyz: [f64; 3],
    pub quat: [f64; 4],
}

/// A shape of an arm link in its joint's frame (mesh links; the shipped arm's links are
/// capsules of `link_radius` instead).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkShape {
    pub geometry: Geometry,
    pub pose: PoseDesc,
    pub color: [f32; 3],
    /// Whether it collides; otherwise it is only drawn.
    pub collides: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum Geometry {
    /// A mesh file (STL, OBJ, glTF) with its per-axis scale; collides and renders as its convex
    /// hull.
    Mesh {
        file: PathBuf,
        scale: [f64; 3],
    },
    /// Full sizes.
    Box {
        size: [f64; 3],
    },
    /// Along z.
    Cylinder {
        radius: f64,
        length: f64,
    },
    Capsule {
        radius: f64,
        length: f64,
    },
    Sphere {
        radius: f64,
    },
}

/// A revolute joint about one axis of its (zero-configuration) frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointDesc {
    pub name: String,
    /// Offset from the previous joint's frame (or the mount) at zero configuration.
    pub origin: [f64; 3],
    /// Rotation of this joint's frame against the previous one at zero configuration, `w, x, y,
    /// z` (`None`: parallel).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[f64; 4]>,
    pub axis: Axis,
    /// `[lower, upper]` in radians.
    pub limits: [f64; 2],
    /// rad/s.
    pub max_velocity: f64,
    /// Largest torque the joint's servo gives (N·m).
    #[serde(default)]
    pub effort: f64,
    /// Mass of the link this joint turns, with the frames fixed to it (kg, the description's
    /// inertials); `None` where the description gives none. The physical grasp mode's arm uses it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mass: Option<f64>,
    /// Radius of the capsule from this joint to the next one (or to the palm); unused where
    /// `shapes` are given.
    pub link_radius: f64,
    /// The link's own shapes in this joint's frame (mesh links); empty: the capsule.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub shapes: Vec<LinkShape>,
}

/// A joint axis in its own frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
    /// Any other direction (unit length).
    Along([f64; 3]),
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
    /// The unit vector along this axis.
    pub fn unit(self) -> [f64; 3] {
        match self {
            Axis::X => [1.0, 0.0, 0.0],
            Axis::Y => [0.0, 1.0, 0.0],
            Axis::Z => [0.0, 0.0, 1.0],
            Axis::Along(v) => v,
        }
    }
}

/// The most arm joints the twin drives (a redundant 7-joint arm).
pub const MAX_ARM_JOINTS: usize = 7;

/// The tree of frames of a URDF or MJCF file, by its extension.
fn description_tree(path: &Path) -> Result<tree::Tree, ContentError> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    match ext.to_ascii_lowercase().as_str() {
        "urdf" => urdf::tree(path),
        "xml" | "mjcf" => mjcf::tree(path),
        _ => Err(ContentError::Invalid {
            path: path.to_path_buf(),
            message: format!("unknown robot format {ext:?}: name a URDF (.urdf) or MJCF (.xml, .mjcf) file"),
        }),
    }
}

/// Where a robot file named in a config lies: relative to the assets directory `assets`, or
/// absolute.
pub fn resolve(assets: &Path, file: &Path) -> PathBuf {
    if file.is_absolute() {
        file.to_path_buf()
    } else {
        assets.join(file)
    }
}

impl RobotDesc {
    /// Load and validate a robot from a URDF (`.urdf`) or MJCF (`.xml`, `.mjcf`) file and its
    /// sidecar (the same path with `.toml`), or from a mounting sidecar (`.toml`) that names an
    /// arm file and a gripper file ([`mounted`]).
    pub fn load(path: &Path) -> Result<RobotDesc, ContentError> {
        let invalid = |message: String| ContentError::Invalid {
            path: path.to_path_buf(),
            message,
        };
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if ext.eq_ignore_ascii_case("toml") {
            let desc = mounted::load(path)?;
            desc.validate().map_err(invalid)?;
            return Ok(desc);
        }
        let tree = description_tree(path)?;
        let side = sidecar::Sidecar::load(path)?;
        let desc = chain::assemble(&tree, &side).map_err(invalid)?;
        desc.validate().map_err(invalid)?;
        Ok(desc)
    }

    /// The shipped robot ([`SHIPPED`] in the assets directory).
    pub fn load_default() -> Result<RobotDesc, ContentError> {
        RobotDesc::load(&crate::assets::assets_dir().join(SHIPPED))
    }

    /// What the twin needs of any robot beyond what the mapping checks.
    pub fn validate(&self) -> Result<(), String> {
        if !(6..=MAX_ARM_JOINTS).contains(&self.arm.joints.len()) {
            return Err(format!(
                "the arm needs 6 or 7 revolute joints, got {}",
                self.arm.joints.len()
            ));
        }
        if self.arm.home.len() != self.arm.joints.len() {
            return Err("[arm] home in the sidecar needs one value per arm joint".into());
        }
        for (j, h) in self.arm.joints.iter().zip(&self.arm.home) {
            if j.limits[0] >= j.limits[1] || *h < j.limits[0] || *h > j.limits[1] || j.max_velocity <= 0.0 {
                return Err(format!(
                    "joint {:?}: need lower < upper, a home value inside them and a velocity limit > 0",
                    j.name
                ));
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
        .any(|v| v.is_nan() || *v <= 0.0)
        {
            return Err("base sizes, mass and limits must be positive".into());
        }
        let g = &self.gripper;
        if g.max_opening <= 0.0 || g.grasp_threshold >= g.release_threshold || g.release_threshold > 1.0 {
            return Err("gripper: need max_opening > 0 and grasp_threshold < release_threshold <= 1".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
