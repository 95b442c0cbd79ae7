//! A robot assembled from descriptions as the field ships them: a mounting sidecar (`.toml`)
//! names an arm file and a gripper file (URDF or MJCF, e.g. robosuite's `robot.xml` and
//! `grippers/*.xml`) and mounts them on the twin's differential-drive base (the shipped robot's
//! body and column) with what neither file says: the arm's mount pose on the base, the frame the
//! gripper hangs from, the tool frame and its turn into the twin's convention (x approach, y
//! closing), the home pose, velocity and effort limits and the gripper's grasp volume.
//!
//! File names may start with `${VAR}` (an environment variable, e.g. `${ROBOSUITE_ASSETS}` for
//! the unpacked robosuite wheel's `robosuite/models/assets`); other relative names are relative
//! to the sidecar. The gripper file's root frame (its world) is fixed to the arm's `tip` frame,
//! as robosuite attaches grippers; the gripper's shapes fixed to it (palm, housing) are drawn and
//! collide with the last link, its moving fingers are the twin's parallel box fingers.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::chain::{first_colour, joint, link_colour, walk};
use super::frame::{Frame, rpy};
use super::shapes::{fixed_frames, link_shapes};
use super::sidecar::Base;
use super::tree::{JointKind, Tree};
use super::{ArmDesc, GripperDesc, PoseDesc, RobotDesc, description_tree};
use crate::ContentError;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct Mounting {
    base: Base,
    arm: MountedArm,
    gripper: MountedGripper,
}

/// A pose in the sidecar: translation (m) and URDF-style `rpy` (rad).
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Pose {
    #[serde(default)]
    xyz: [f64; 3],
    #[serde(default)]
    rpy: [f64; 3],
}

impl Pose {
    fn frame(&self) -> Frame {
        Frame::new(self.xyz, rpy(self.rpy))
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct MountedArm {
    file: String,
    /// The arm file's frame that is bolted to the base.
    root: String,
    /// The frame the gripper hangs from.
    tip: String,
    /// `root` in the twin's base frame.
    mount: Pose,
    home: Vec<f64>,
    max_velocity: Vec<f64>,
    effort: Vec<f64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct MountedGripper {
    file: String,
    /// The gripper file's tool frame (between the fingertips).
    tool: String,
    /// Turns the file's tool frame into the twin's: x approach, y closing axis.
    #[serde(default)]
    tool_turn: Pose,
    /// From the hand frame (where the palm box sits behind) to the tool centre point, m.
    tcp_offset: f64,
    palm_size: [f64; 3],
    palm_back: f64,
    finger_length: f64,
    finger_thickness: f64,
    finger_height: f64,
    /// Widest finger gap (m); by default the sum of the gripper file's slide joint travels.
    #[serde(default)]
    max_opening: Option<f64>,
    opening_speed: f64,
    grasp_threshold: f64,
    release_threshold: f64,
}

/// `${VAR}/rest` with the variable's value, other relative names against `dir`.
pub(crate) fn resolve_file(dir: &Path, name: &str, sidecar: &Path) -> Result<PathBuf, ContentError> {
    if let Some(rest) = name.strip_prefix("${") {
        let (var, tail) = rest.split_once('}').ok_or_else(|| ContentError::Invalid {
            path: sidecar.to_path_buf(),
            message: format!("{name:?}: close the variable name with '}}'"),
        })?;
        let value = std::env::var_os(var).ok_or_else(|| ContentError::Invalid {
            path: sidecar.to_path_buf(),
            message: format!(
                "{name:?} names the environment variable {var}, which is not set; for robosuite's robots set \
                 ROBOSUITE_ASSETS to the unpacked robosuite==1.5.2 wheel's robosuite/models/assets \
                 (scripts/robosuite-assets.sh fetches it)"
            ),
        })?;
        return Ok(PathBuf::from(value).join(tail.trim_start_matches('/')));
    }
    Ok(dir.join(name))
}

pub(crate) fn load(path: &Path) -> Result<RobotDesc, ContentError> {
    let text = std::fs::read_to_string(path).map_err(|source| ContentError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let m: Mounting = toml::from_str(&text).map_err(|e| ContentError::Parse {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let arm_file = resolve_file(dir, &m.arm.file, path)?;
    let grip_file = resolve_file(dir, &m.gripper.file, path)?;
    let arm_tree = description_tree(&arm_file)?;
    let grip_tree = description_tree(&grip_file)?;
    let in_arm = |message: String| ContentError::Invalid {
        path: arm_file.clone(),
        message,
    };
    let in_grip = |message: String| ContentError::Invalid {
        path: grip_file.clone(),
        message,
    };
    let in_side = |message: String| ContentError::Invalid {
        path: path.to_path_buf(),
        message,
    };
    let arm = mount_arm(&arm_tree, &m.arm).map_err(in_arm)?;
    let (hand_frame, hand_shapes, opening) = mount_gripper(&grip_tree, &m.gripper).map_err(in_grip)?;
    let ArmParts {
        mut desc,
        tip_from_last,
    } = arm;
    let g = &m.gripper;
    // Tool frame in the last joint's frame, turned into the twin's convention; the hand frame
    // sits tcp_offset behind it along its x.
    let tool = tip_from_last.then(&hand_frame).then(&g.tool_turn.frame());
    let flange = tool.then(&Frame::new([-g.tcp_offset, 0.0, 0.0], super::tree::IDENTITY));
    desc.flange = Some(PoseDesc {
        xyz: flange.t,
        quat: flange.rotation(),
    });
    desc.hand_shapes = hand_shapes
        .into_iter()
        .map(|mut s| {
            let at = tip_from_last.then(&Frame::new(s.pose.xyz, s.pose.quat));
            s.pose = PoseDesc {
                xyz: at.t,
                quat: at.rotation(),
            };
            s
        })
        .collect();
    let max_opening = g.max_opening.or(opening).ok_or_else(|| {
        in_side(
            "[gripper] max_opening: the gripper file has no slide finger joints to measure the widest gap by; \
             give it in metres"
                .into(),
        )
    })?;
    let shipped = super::RobotDesc::load_default()?;
    let mut base = shipped.base;
    let b = &m.base;
    (
        base.radius,
        base.max_v,
        base.max_omega,
        base.acc_v,
        base.acc_omega,
    ) = (b.radius, b.max_v, b.max_omega, b.acc_v, b.acc_omega);
    Ok(RobotDesc {
        base,
        arm: desc,
        gripper: GripperDesc {
            tcp_offset: g.tcp_offset,
            palm_size: g.palm_size,
            palm_back: g.palm_back,
            finger_length: g.finger_length,
            finger_thickness: g.finger_thickness,
            finger_height: g.finger_height,
            max_opening,
            opening_speed: g.opening_speed,
            grasp_threshold: g.grasp_threshold,
            release_threshold: g.release_threshold,
            color: shipped.gripper.color,
        },
    })
}

struct ArmParts {
    desc: ArmDesc,
    /// The tip frame in the last joint's frame.
    tip_from_last: Frame,
}

fn find(t: &Tree, name: &str, key: &str) -> Result<usize, String> {
    t.find(name).ok_or_else(|| {
        format!(
            "no <{} name=\"{name}\"> (or site): {key} in the sidecar names one of this file's {}s",
            t.frame_tag, t.frame_tag
        )
    })
}

fn mount_arm(t: &Tree, a: &MountedArm) -> Result<ArmParts, String> {
    let root = find(t, &a.root, "[arm] root")?;
    let tip = find(t, &a.tip, "[arm] tip")?;
    let chain = walk(t, root, tip)?;
    let n = chain.arm.len();
    for (key, len) in [
        ("home", a.home.len()),
        ("max_velocity", a.max_velocity.len()),
        ("effort", a.effort.len()),
    ] {
        if len != n {
            return Err(format!(
                "the arm has {n} joints but the sidecar's [arm] {key} gives {len} values: give one per joint"
            ));
        }
    }
    let side = super::sidecar::Arm {
        home: a.home.clone(),
        max_velocity: Some(a.max_velocity.clone()),
        effort: Some(a.effort.clone()),
    };
    let next: Vec<usize> = chain.arm.iter().map(|j| j.child).collect();
    let joints = chain
        .arm
        .iter()
        .enumerate()
        .map(|(i, j)| joint(t, &side, i, j, &next))
        .collect::<Result<Vec<_>, _>>()?;
    let mount = a.mount.frame().then(&chain.mount);
    Ok(ArmParts {
        desc: ArmDesc {
            mount: mount.t,
            mount_rotation: mount.q,
            home: a.home.clone(),
            color: link_colour(t, chain.arm[0].child),
            joints,
            flange: None,
            hand_shapes: Vec::new(),
        },
        tip_from_last: chain.tcp,
    })
}

/// The tool frame in the gripper file's root frame, the shapes fixed to the root (in it), and
/// the widest gap its slide finger joints give.
fn mount_gripper(
    t: &Tree,
    g: &MountedGripper,
) -> Result<(Frame, Vec<super::LinkShape>, Option<f64>), String> {
    let root = 0;
    let tool = find(t, &g.tool, "[gripper] tool")?;
    let set = fixed_frames(t, root, &[]);
    let tool_frame = set
        .iter()
        .find(|(l, _)| *l == tool)
        .map(|(_, f)| *f)
        .ok_or_else(|| {
            format!(
                "{} is not fixed to the gripper's root: name a frame (or site) on the palm, not on a finger",
                t.frame(tool)
            )
        })?;
    let colour = set.iter().find_map(|(l, _)| first_colour(t, *l));
    let shapes = link_shapes(t, &set, &Frame::IDENTITY, colour)?;
    let slides: Vec<f64> = set
        .iter()
        .flat_map(|(l, _)| t.children(*l))
        .filter(|(_, j)| j.kind == JointKind::Prismatic)
        .filter_map(|(_, j)| j.limits.map(|[lo, hi]| hi - lo))
        .collect();
    let opening = (!slides.is_empty()).then(|| slides.iter().sum());
    Ok((tool_frame, shapes, opening))
}
