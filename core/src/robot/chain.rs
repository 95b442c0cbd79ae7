//! From a description's tree of frames to [`RobotDesc`]: the serial chain from the base frame to
//! the tool frame must be fixed joints and six or seven revolute joints. Frames on it may be
//! rotated (URDF `rpy`, MJCF `quat`/`euler`/`axisangle`) and joints turn about any axis; where
//! none is rotated the joint origins reach the kinematics exactly as the file writes them.
//!
//! Where the twin's parts are found:
//! - base: the frames fixed to the base frame hold one cylinder (the body, standing on the base
//!   centre) and one box (the arm's column); their masses add up to the base's mass;
//! - arm: joint i's child frame holds a capsule or cylinder whose radius is link i's, or else
//!   its shapes (meshes, boxes...) on it and the frames fixed to it are link i's;
//! - hand: the frames fixed to the last arm link hold one box (the palm, on the last joint's x
//!   axis) and are the parents of two prismatic finger joints (`lower` 0, `upper` half the widest
//!   gap) whose child frames hold each a box (length, thickness, height);
//! - tool: the tool frame lies on the last joint's +x axis (`tcp_offset` from it).

use super::frame::Frame;
use super::shapes::{fixed_frames, link_shapes, rgb};
use super::sidecar::Sidecar;
use super::tree::{Geom, JointKind, Shape, Tree, add};
use super::{ArmDesc, Axis, BaseDesc, GripperDesc, JointDesc, MAX_ARM_JOINTS, RobotDesc};

/// The serial chain from the base frame to the tool frame: the mount (base frame to the first
/// joint), the arm's joints, and the tool's transform from the last joint.
pub(crate) struct Chain<'a> {
    pub mount: Frame,
    pub arm: Vec<ArmJoint<'a>>,
    pub tcp: Frame,
}

/// One revolute joint of the arm: its child frame, the joint, its frame from the previous joint.
pub(crate) struct ArmJoint<'a> {
    pub child: usize,
    pub joint: &'a super::tree::Joint,
    pub origin: Frame,
}

pub(crate) fn assemble(t: &Tree, s: &Sidecar) -> Result<RobotDesc, String> {
    let base = named(
        t,
        &s.frames.base,
        "base",
        "the robot base frame (origin at the base centre on the floor)",
    )?;
    let tool = named(
        t,
        &s.frames.tool,
        "tool",
        "the tool frame (between the fingertips, x out of them)",
    )?;
    let Chain { mount, arm, tcp } = walk(t, base, tool)?;
    let next: Vec<usize> = arm.iter().map(|a| a.child).collect();
    let joints = arm
        .iter()
        .enumerate()
        .map(|(i, a)| joint(t, &s.arm, i, a, &next))
        .collect::<Result<Vec<_>, _>>()?;
    if tcp.q.is_some() || tcp.t[1] != 0.0 || tcp.t[2] != 0.0 || tcp.t[0] <= 0.0 {
        return Err(format!(
            "{} sits at {:?} from the last arm joint's frame: the tool frame must lie on that frame's +x \
             axis (y = z = 0, x > 0), unrotated (or mount the arm and its gripper from a sidecar of their \
             own: docs/twin/robot.md)",
            t.frame(tool),
            tcp.t
        ));
    }
    let arm_color = link_colour(t, arm[0].child);
    let gripper = hand(t, s, arm[arm.len() - 1].child, tcp.t[0])?;
    Ok(RobotDesc {
        base: base_desc(t, s, base)?,
        arm: ArmDesc {
            mount: mount.t,
            mount_rotation: mount.q,
            home: s.arm.home.clone(),
            color: arm_color,
            joints,
            flange: None,
            hand_shapes: Vec::new(),
        },
        gripper,
    })
}

/// The colour of a link: its capsule's, or its first coloured shape's.
pub(crate) fn link_colour(t: &Tree, link: usize) -> [f32; 3] {
    match capsule(t, link) {
        Ok(g) => rgb(g.color),
        Err(_) => rgb(first_colour(t, link)),
    }
}

/// The first colour a geom of `link` (or a frame fixed to it) gives.
pub(crate) fn first_colour(t: &Tree, link: usize) -> Option<[f64; 4]> {
    fixed_frames(t, link, &[])
        .iter()
        .flat_map(|(l, _)| t.links[*l].geoms.iter())
        .find_map(|g| g.color)
}

fn named(t: &Tree, name: &str, key: &str, what: &str) -> Result<usize, String> {
    t.find(name).ok_or_else(|| {
        format!(
            "no <{} name=\"{name}\">: [frames] {key} in the sidecar names {what}; name one of this file's {}s",
            t.frame_tag, t.frame_tag
        )
    })
}

/// The mount, the arm's revolute joints and the tool's transform along the chain from `base` to
/// `tool`.
pub(crate) fn walk(t: &Tree, base: usize, tool: usize) -> Result<Chain<'_>, String> {
    let mut path = vec![tool];
    while *path.last().unwrap_or(&base) != base {
        let at = path[path.len() - 1];
        match &t.links[at].parent {
            Some((p, _)) => path.push(*p),
            None => {
                return Err(format!(
                    "{} does not hang from {}: the tool frame must be below the base frame",
                    t.frame(tool),
                    t.frame(base)
                ));
            }
        }
    }
    path.reverse();
    let (mut acc, mut mount, mut arm) = (Frame::IDENTITY, Frame::IDENTITY, Vec::new());
    for &child in &path[1..] {
        let Some((_, j)) = &t.links[child].parent else {
            continue;
        };
        let own = Frame::new(j.origin, j.rotation);
        match j.kind {
            JointKind::Fixed => acc = acc.then(&own),
            JointKind::Revolute => {
                let before = if arm.is_empty() {
                    mount = acc;
                    Frame::IDENTITY
                } else {
                    acc
                };
                arm.push(ArmJoint {
                    child,
                    joint: j,
                    origin: before.then(&own),
                });
                acc = Frame::IDENTITY;
            }
            JointKind::Prismatic | JointKind::Other(_) => {
                return Err(format!(
                    "<joint name=\"{}\"> ({}) lies between the base frame and the tool frame: the arm is six \
                     revolute joints with limits, and fixed joints",
                    j.name,
                    kind_name(j.kind)
                ));
            }
        }
    }
    if !(6..=MAX_ARM_JOINTS).contains(&arm.len()) {
        let names: Vec<&str> = arm.iter().map(|a| a.joint.name.as_str()).collect();
        return Err(format!(
            "the chain from {} to {} has {} revolute joints {names:?}; the twin's arm has 6 or 7",
            t.frame(base),
            t.frame(tool),
            arm.len()
        ));
    }
    Ok(Chain { mount, arm, tcp: acc })
}

fn kind_name(k: JointKind) -> &'static str {
    match k {
        JointKind::Fixed => "fixed",
        JointKind::Revolute => "revolute",
        JointKind::Prismatic => "prismatic",
        JointKind::Other(n) => n,
    }
}

/// Arm joint `i`; `next` holds every arm joint's child frame (a link's shapes stop there).
pub(crate) fn joint(
    t: &Tree,
    s: &super::sidecar::Arm,
    i: usize,
    a: &ArmJoint<'_>,
    next: &[usize],
) -> Result<JointDesc, String> {
    let j = a.joint;
    let at = |what: &str| format!("<joint name=\"{}\">: {what}", j.name);
    let axis = match j.axis {
        [1.0, 0.0, 0.0] => Axis::X,
        [0.0, 1.0, 0.0] => Axis::Y,
        [0.0, 0.0, 1.0] => Axis::Z,
        v => {
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if n.is_nan() || n <= 1e-9 {
                return Err(at(&format!("axis {v:?}: give a non-zero axis")));
            }
            Axis::Along(v.map(|c| c / n))
        }
    };
    let limits = j
        .limits
        .ok_or_else(|| at("no joint limits: give lower and upper (URDF <limit>, MJCF range)"))?;
    let from_side = |v: &Option<Vec<f64>>| v.as_ref().and_then(|v| v.get(i).copied());
    let max_velocity = j.velocity.or_else(|| from_side(&s.max_velocity)).ok_or_else(|| {
        at("no velocity limit: give URDF <limit velocity>, or max_velocity in the sidecar's [arm] (one per joint)")
    })?;
    let effort = j.effort.or_else(|| from_side(&s.effort)).ok_or_else(|| {
        at("no effort limit: give URDF <limit effort>, or effort in the sidecar's [arm] (one per joint)")
    })?;
    let masses = fixed_to(t, a.child)
        .into_iter()
        .filter_map(|(l, _)| t.links[l].mass);
    let mass = masses.reduce(|x, y| x + y).filter(|m| *m > 0.0);
    let (link_radius, shapes) = match capsule(t, a.child) {
        Ok(g) => match g.shape {
            Shape::Capsule { radius, .. } | Shape::Cylinder { radius, .. } => (radius, Vec::new()),
            _ => unreachable!("capsule() returns capsules and cylinders"),
        },
        Err(_) => {
            // A link of its own shapes, or none (a bare wrist link between two joints, as
            // xArm 7's link7): radius 0 and no shapes is a link without collider.
            let set = fixed_frames(t, a.child, next);
            let shapes = link_shapes(t, &set, &Frame::IDENTITY, first_colour(t, a.child))?;
            (0.0, shapes)
        }
    };
    Ok(JointDesc {
        name: j.name.clone(),
        origin: a.origin.t,
        rotation: a.origin.q,
        axis,
        limits,
        max_velocity,
        effort,
        mass,
        link_radius,
        shapes,
    })
}

/// The arm link's capsule (or cylinder).
fn capsule(t: &Tree, link: usize) -> Result<&Geom, String> {
    t.links[link]
        .geoms
        .iter()
        .find(|g| matches!(g.shape, Shape::Capsule { .. } | Shape::Cylinder { .. }))
        .ok_or_else(|| {
            format!(
                "{} has no capsule or cylinder {} and no other shape: the twin draws each arm link as a capsule \
                 of that radius from its joint to the next, or as its own shapes (meshes, boxes...)",
                t.frame(link),
                t.geom_tag
            )
        })
}

/// `from` and every frame fixed to it, with its offset from `from`.
fn fixed_to(t: &Tree, from: usize) -> Vec<(usize, [f64; 3])> {
    let mut out = vec![(from, [0.0; 3])];
    let mut k = 0;
    while k < out.len() {
        let (at, off) = out[k];
        for (c, j) in t.children(at) {
            if j.kind == JointKind::Fixed && !j.rotated {
                out.push((c, add(off, j.origin)));
            }
        }
        k += 1;
    }
    out
}

/// The one geom of `kind` on the frames of `set`, with its frame's offset from the set's root.
fn only<'a>(
    t: &'a Tree,
    set: &[(usize, [f64; 3])],
    kind: &str,
    part: &str,
) -> Result<(&'a Geom, [f64; 3]), String> {
    let is = |g: &Geom| match g.shape {
        Shape::Box(_) => kind == "box",
        Shape::Cylinder { .. } => kind == "cylinder",
        _ => false,
    };
    let found: Vec<_> = set
        .iter()
        .flat_map(|(l, off)| t.links[*l].geoms.iter().filter(|g| is(g)).map(move |g| (g, *off)))
        .collect();
    match found.as_slice() {
        [one] if !one.0.rotated => Ok(*one),
        [_] => Err(format!("the {part} ({kind}) is rotated: give it no rotation")),
        _ => Err(format!(
            "{} {kind} {}s on {} and the frames fixed to it, the twin needs one: the {part}",
            found.len(),
            t.geom_tag,
            t.frame(set[0].0)
        )),
    }
}

fn base_desc(t: &Tree, s: &Sidecar, base: usize) -> Result<BaseDesc, String> {
    let set = fixed_to(t, base);
    let (body, off) = only(t, &set, "cylinder", "base's body")?;
    let Shape::Cylinder { radius, length } = body.shape else {
        unreachable!("only() found a cylinder")
    };
    let at = add(off, body.origin);
    if at[0] != 0.0 || at[1] != 0.0 {
        return Err(format!(
            "the base's body cylinder stands at {at:?}: centre it on the base frame (x = y = 0)"
        ));
    }
    // The frame's height plus the cylinder's bottom in it, in this order: a body frame at the
    // clearance with the cylinder standing on it gives the clearance exactly.
    let clearance = off[2] + (body.origin[2] - length / 2.0);
    let (column, off) = only(t, &set, "box", "arm's column")?;
    let Shape::Box(column_size) = column.shape else {
        unreachable!("only() found a box")
    };
    let column_center = add(off, column.origin);
    let mass: f64 = set
        .iter()
        .filter_map(|(l, _)| t.links[*l].mass)
        .fold(0.0, |a, m| a + m);
    if mass <= 0.0 {
        return Err(format!(
            "{} and the frames fixed to it have no mass: give the base an inertial mass",
            t.frame(base)
        ));
    }
    let b = &s.base;
    Ok(BaseDesc {
        radius: b.radius,
        body_radius: radius,
        height: clearance + length,
        clearance,
        mass,
        max_v: b.max_v,
        max_omega: b.max_omega,
        acc_v: b.acc_v,
        acc_omega: b.acc_omega,
        column_center,
        column_size,
        color: rgb(body.color),
    })
}

fn hand(t: &Tree, s: &Sidecar, last: usize, tcp: f64) -> Result<GripperDesc, String> {
    let set = fixed_to(t, last);
    let (palm, off) = only(t, &set, "box", "palm")?;
    let Shape::Box(palm_size) = palm.shape else {
        unreachable!("only() found a box")
    };
    let at = add(off, palm.origin);
    if at[1] != 0.0 || at[2] != 0.0 {
        return Err(format!(
            "the palm box sits at {at:?}: put it on the last arm joint's x axis (y = z = 0)"
        ));
    }
    let fingers: Vec<_> = set
        .iter()
        .flat_map(|(l, _)| t.children(*l))
        .filter(|(_, j)| j.kind == JointKind::Prismatic)
        .collect();
    let [(left, lj), (_, rj)] = fingers.as_slice() else {
        return Err(format!(
            "{} prismatic finger joints on {} and the frames fixed to it: the gripper needs two",
            fingers.len(),
            t.frame(last)
        ));
    };
    let travel = |j: &super::tree::Joint| match j.limits {
        Some([lo, hi]) if lo == 0.0 && hi > 0.0 => Ok(hi),
        _ => Err(format!(
            "<joint name=\"{}\">: a finger's limits are lower 0 (closed) and upper half the widest gap",
            j.name
        )),
    };
    let half = travel(lj)?;
    if travel(rj)? != half {
        return Err(format!(
            "<joint name=\"{}\">: both fingers need the same upper limit",
            rj.name
        ));
    }
    let finger = t.links[*left]
        .geoms
        .iter()
        .find_map(|g| match g.shape {
            Shape::Box(size) => Some(size),
            _ => None,
        })
        .ok_or_else(|| format!("{} has no box {}: the finger's size", t.frame(*left), t.geom_tag))?;
    let g = &s.gripper;
    Ok(GripperDesc {
        tcp_offset: tcp,
        palm_size,
        palm_back: tcp - at[0],
        finger_length: finger[0],
        finger_thickness: finger[1],
        finger_height: finger[2],
        max_opening: 2.0 * half,
        opening_speed: g.opening_speed,
        grasp_threshold: g.grasp_threshold,
        release_threshold: g.release_threshold,
        color: rgb(palm.color),
    })
}
