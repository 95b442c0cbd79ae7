//! From a description's tree of frames to [`RobotDesc`]: the serial chain from the base frame to
//! the tool frame must be fixed joints and exactly six revolute joints, every frame on it parallel
//! to the base frame at the zero configuration (translations only), so the joint origins reach the
//! kinematics as the file writes them.
//!
//! Where the twin's parts are found:
//! - base: the frames fixed to the base frame hold one cylinder (the body, standing on the base
//!   centre) and one box (the arm's column); their masses add up to the base's mass;
//! - arm: joint i's child frame holds a capsule or cylinder whose radius is link i's;
//! - hand: the frames fixed to the last arm link hold one box (the palm, on the last joint's x
//!   axis) and are the parents of two prismatic finger joints (`lower` 0, `upper` half the widest
//!   gap) whose child frames hold each a box (length, thickness, height);
//! - tool: the tool frame lies on the last joint's +x axis (`tcp_offset` from it).

use super::sidecar::Sidecar;
use super::tree::{Geom, JointKind, Shape, Tree, add};
use super::{ArmDesc, Axis, BaseDesc, GripperDesc, JointDesc, RobotDesc};

/// Colour of a part whose file gives none.
const GREY: [f32; 3] = [0.5, 0.5, 0.5];

/// The serial chain from the base frame to the tool frame: the mount (base frame to the first
/// joint), the six joints, and the tool offset from the last joint.
struct Chain<'a> {
    mount: [f64; 3],
    arm: Vec<ArmJoint<'a>>,
    tcp: [f64; 3],
}

/// One revolute joint of the arm: its child frame, the joint, its origin from the previous joint.
struct ArmJoint<'a> {
    child: usize,
    joint: &'a super::tree::Joint,
    origin: [f64; 3],
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
    let joints = arm
        .iter()
        .enumerate()
        .map(|(i, a)| joint(t, s, i, a))
        .collect::<Result<Vec<_>, _>>()?;
    if tcp[1] != 0.0 || tcp[2] != 0.0 || tcp[0] <= 0.0 {
        return Err(format!(
            "{} sits at {tcp:?} from the last arm joint's frame: the tool frame must lie on that frame's +x \
             axis (y = z = 0, x > 0)",
            t.frame(tool)
        ));
    }
    let arm_color = rgb(capsule(t, arm[0].child)?.color);
    let gripper = hand(t, s, arm[5].child, tcp[0])?;
    Ok(RobotDesc {
        base: base_desc(t, s, base)?,
        arm: ArmDesc {
            mount,
            home: s.arm.home.clone(),
            color: arm_color,
            joints,
        },
        gripper,
    })
}

fn named(t: &Tree, name: &str, key: &str, what: &str) -> Result<usize, String> {
    t.find(name).ok_or_else(|| {
        format!(
            "no <{} name=\"{name}\">: [frames] {key} in the sidecar names {what}; name one of this file's {}s",
            t.frame_tag, t.frame_tag
        )
    })
}

/// The mount, the six revolute joints and the tool offset along the chain from `base` to `tool`.
fn walk(t: &Tree, base: usize, tool: usize) -> Result<Chain<'_>, String> {
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
    let (mut acc, mut mount, mut arm) = ([0.0; 3], [0.0; 3], Vec::new());
    for &child in &path[1..] {
        let Some((_, j)) = &t.links[child].parent else {
            continue;
        };
        if j.rotated {
            return Err(format!(
                "<joint name=\"{}\"> turns its child frame: from the base frame to the tool frame every frame \
                 must be parallel to the base frame at the zero configuration; set its rotation to zero and \
                 give the axis in the base frame's directions",
                j.name
            ));
        }
        match j.kind {
            JointKind::Fixed => acc = add(acc, j.origin),
            JointKind::Revolute => {
                let before = if arm.is_empty() {
                    mount = acc;
                    [0.0; 3]
                } else {
                    acc
                };
                arm.push(ArmJoint {
                    child,
                    joint: j,
                    origin: add(before, j.origin),
                });
                acc = [0.0; 3];
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
    if arm.len() != 6 {
        let names: Vec<&str> = arm.iter().map(|a| a.joint.name.as_str()).collect();
        return Err(format!(
            "the chain from {} to {} has {} revolute joints {names:?}; the twin's arm has exactly 6",
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

fn joint(t: &Tree, s: &Sidecar, i: usize, a: &ArmJoint<'_>) -> Result<JointDesc, String> {
    let j = a.joint;
    let at = |what: &str| format!("<joint name=\"{}\">: {what}", j.name);
    let axis = match j.axis {
        [1.0, 0.0, 0.0] => Axis::X,
        [0.0, 1.0, 0.0] => Axis::Y,
        [0.0, 0.0, 1.0] => Axis::Z,
        other => {
            return Err(at(&format!(
                "axis {other:?}: an arm joint turns about +x, +y or +z of its frame (\"1 0 0\", \"0 1 0\" or \"0 0 1\")"
            )));
        }
    };
    let limits = j
        .limits
        .ok_or_else(|| at("no joint limits: give lower and upper (URDF <limit>, MJCF range)"))?;
    let from_side = |v: &Option<Vec<f64>>| v.as_ref().and_then(|v| v.get(i).copied());
    let max_velocity = j.velocity.or_else(|| from_side(&s.arm.max_velocity)).ok_or_else(|| {
        at("no velocity limit: give URDF <limit velocity>, or max_velocity in the sidecar's [arm] (one per joint)")
    })?;
    let effort = j.effort.or_else(|| from_side(&s.arm.effort)).ok_or_else(|| {
        at("no effort limit: give URDF <limit effort>, or effort in the sidecar's [arm] (one per joint)")
    })?;
    let masses = fixed_to(t, a.child)
        .into_iter()
        .filter_map(|(l, _)| t.links[l].mass);
    let mass = masses.reduce(|x, y| x + y).filter(|m| *m > 0.0);
    Ok(JointDesc {
        name: j.name.clone(),
        origin: a.origin,
        axis,
        limits,
        max_velocity,
        effort,
        mass,
        link_radius: match capsule(t, a.child)?.shape {
            Shape::Capsule { radius } | Shape::Cylinder { radius, .. } => radius,
            _ => unreachable!("capsule() returns capsules and cylinders"),
        },
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
                "{} has no capsule or cylinder {}: the twin draws each arm link as a capsule of that radius from \
                 its joint to the next",
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

fn rgb(c: Option<[f64; 4]>) -> [f32; 3] {
    c.map_or(GREY, |c| [c[0] as f32, c[1] as f32, c[2] as f32])
}
