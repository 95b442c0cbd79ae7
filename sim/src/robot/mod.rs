//! The robot in the physics world: a velocity-driven differential-drive base, the arm's links
//! placed from the RMP controller's integrated joint targets, and the parallel gripper.
//!
//! The base is a dynamic body with roll, pitch and height locked whose planar velocity is set
//! every substep to the (acceleration- and speed-limited) command, so the contact solver stops it
//! at walls and furniture and lets it push loose objects. The arm links are weightless dynamic
//! bodies whose velocities are set every substep to reach their poses from the joint position
//! targets (an ideal position-controlled articulation). A higher dominance group lets them push
//! loose objects like a stiff arm while fixed geometry still stops them; a link that digs into
//! fixed furniture or a wall also reverts the joint targets to the last collision-free
//! configuration, so the controller does not wind up against it.

pub mod articulated;
pub mod clearance;
pub mod desc;
pub mod ik;
pub mod kinematics;
mod obstacles;
pub mod palm;
pub mod rmp;
pub mod wrist;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;

use crate::convert::{iso_to_pose, planar, pose_to_iso, vec_to_glam, yaw_of};
use crate::material::{Material, Materials, Owner, Tag};
use desc::RobotDesc;
use kinematics::{ArmModel, JointVec};
use rmp::{ArmState, RmpParams};

mod links;

use obstacles::{is_static, placed};

/// Names of the robot parts, indexed by the collider tag's `index` (a seven-joint arm's last
/// link is `link7`, after the gripper's parts, so the six-joint indices stay as they are).
pub const PART_NAMES: [&str; 11] = [
    "base",
    "waist",
    "shoulder",
    "elbow",
    "forearm_roll",
    "wrist_angle",
    "wrist_rotate",
    "palm",
    "left_finger",
    "right_finger",
    "link7",
];
const PALM: u32 = 7;
const FINGERS: [u32; 2] = [8, 9];

/// Arm links outrank objects in contacts (they move them like an ideal position-controlled arm)
/// and are outranked by fixed geometry (which stops them).
const LINK_DOMINANCE: i8 = 10;

/// Height (m) plus tilt (rad) of the base away from the floor plane beyond which it is put back.
const PLANAR_TOLERANCE: f64 = 1e-6;

/// A link penetrating fixed geometry deeper than this stops the arm (m).
const STOP_PENETRATION: f64 = 0.003;

/// Handles of the robot's bodies in the world.
#[derive(Debug, Clone)]
pub struct RobotBodies {
    pub base: RigidBodyHandle,
    /// One body per arm joint, base to tool.
    pub links: Vec<RigidBodyHandle>,
    pub fingers: [ColliderHandle; 2],
    /// Every arm collider with the index of the link it belongs to.
    pub arm_colliders: Vec<(ColliderHandle, usize)>,
    /// The motor-driven multibody of the physical grasp mode (`None`: the abstract mode's arm).
    pub articulation: Option<articulated::Articulation>,
}

/// Controller state that is not in the physics world (part of snapshots and state hashes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotState {
    pub arm: ArmState,
    /// Last joint targets known to be collision-free.
    pub safe_q: JointVec,
    /// Commanded, rate-limited base velocities.
    pub v: f64,
    pub omega: f64,
    /// Current finger gap (m).
    pub opening: f64,
    /// Set when the arm was stopped by fixed geometry in the last substep.
    pub arm_blocked: bool,
}

/// The robot model plus its handles.
#[derive(Debug, Clone)]
pub struct Robot {
    pub desc: RobotDesc,
    pub arm: ArmModel,
    pub home: JointVec,
    pub bodies: RobotBodies,
}

fn collider(shape: SharedShape, part: u32, material: u32, finger: bool) -> ColliderBuilder {
    ColliderBuilder::new(shape)
        .friction(if part == 0 { 0.0 } else { 0.8 })
        .collision_groups(Owner::Robot.groups(finger))
        .user_data(
            Tag {
                material,
                owner: Owner::Robot,
                index: part,
            }
            .pack(),
        )
}

impl Robot {
    /// Insert the robot at planar pose `[x, y, yaw]` with the arm at home.
    pub fn spawn(
        world: &mut PhysicsWorld,
        mats: &mut Materials,
        desc: &RobotDesc,
        start: [f64; 3],
    ) -> (Robot, RobotState) {
        let arm = ArmModel::new(desc);
        let home = arm.vec(&desc.arm.home);
        let b = &desc.base;
        let base_iso = planar(start[0], start[1], 0.0, start[2]);
        let base = world.insert_body(
            RigidBodyBuilder::dynamic()
                .pose(iso_to_pose(&base_iso))
                .locked_axes(
                    LockedAxes::TRANSLATION_LOCKED_Z
                        | LockedAxes::ROTATION_LOCKED_X
                        | LockedAxes::ROTATION_LOCKED_Y,
                )
                .gravity_scale(0.0)
                .can_sleep(false),
        );
        let body_mat = mats.add(Material::plain(b.color));
        let half_h = (b.height - b.clearance) / 2.0;
        let upright = UnitQuaternion::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0);
        let cyl = Isometry3::from_parts(Translation3::new(0.0, 0.0, b.clearance + half_h), upright);
        let co = collider(
            SharedShape::cylinder(half_h as f32, b.body_radius as f32),
            0,
            body_mat,
            false,
        )
        .position(iso_to_pose(&cyl))
        .mass(b.mass as f32 * 0.9);
        world.insert_collider(co, Some(base));
        let cs = b.column_size.map(|v| v as f32 / 2.0);
        let co = collider(SharedShape::cuboid(cs[0], cs[1], cs[2]), 0, body_mat, false)
            .translation(vec_to_glam(&Vector3::from(b.column_center)))
            .mass(b.mass as f32 * 0.1);
        world.insert_collider(co, Some(base));

        let state = RobotState {
            arm: ArmState {
                q: home,
                qd: JointVec::zeros(),
            },
            safe_q: home,
            v: 0.0,
            omega: 0.0,
            opening: desc.gripper.max_opening,
            arm_blocked: false,
        };
        let fk = arm.forward(&home);
        let arm_mat = mats.add(Material::plain(desc.arm.color));
        let grip_mat = mats.add(Material::plain(desc.gripper.color));
        let mut arm_colliders = Vec::new();
        let mut fingers = [ColliderHandle::invalid(); 2];
        let links = (0..arm.dof)
            .map(|i| {
                let pose = base_iso * fk.joints[i];
                let h = world.insert_body(
                    RigidBodyBuilder::dynamic()
                        .pose(iso_to_pose(&pose))
                        .gravity_scale(0.0)
                        .dominance_group(LINK_DOMINANCE)
                        .can_sleep(false),
                );
                for co in links::link_colliders(desc, &arm, i, arm_mat, mats) {
                    arm_colliders.push((world.insert_collider(co, Some(h)), i));
                }
                if i == arm.dof - 1 {
                    let palm = links::palm(desc, &arm, grip_mat);
                    arm_colliders.push((world.insert_collider(palm, Some(h)), i));
                    for (k, part) in FINGERS.iter().enumerate() {
                        let g = &desc.gripper;
                        let fs =
                            [g.finger_length, g.finger_thickness, g.finger_height].map(|v| v as f32 / 2.0);
                        let co = collider(SharedShape::cuboid(fs[0], fs[1], fs[2]), *part, grip_mat, true);
                        fingers[k] = world.insert_collider(co, Some(h));
                        arm_colliders.push((fingers[k], i));
                    }
                }
                h
            })
            .collect();
        let robot = Robot {
            desc: desc.clone(),
            arm,
            home,
            bodies: RobotBodies {
                base,
                links,
                fingers,
                arm_colliders,
                articulation: None,
            },
        };
        robot.place_fingers(world, state.opening);
        (robot, state)
    }

    /// Base pose in the world (from the physics body).
    pub fn base_iso(&self, world: &PhysicsWorld) -> Isometry3<f64> {
        pose_to_iso(world.bodies[self.bodies.base].position())
    }

    /// `[x, y, yaw]` of the base centre.
    pub fn base_pose(&self, world: &PhysicsWorld) -> [f64; 3] {
        let iso = self.base_iso(world);
        [iso.translation.x, iso.translation.y, yaw_of(&iso.rotation)]
    }

    /// Measured planar base velocities `(v, omega)`.
    pub fn base_velocity(&self, world: &PhysicsWorld) -> (f64, f64) {
        let body = &world.bodies[self.bodies.base];
        let iso = self.base_iso(world);
        let fwd = iso.rotation * Vector3::x();
        let lv = body.linvel();
        (
            fwd.x * f64::from(lv.x) + fwd.y * f64::from(lv.y),
            f64::from(body.angvel().z),
        )
    }

    fn place_fingers(&self, world: &mut PhysicsWorld, opening: f64) {
        let g = &self.desc.gripper;
        let tcp = self.desc.gripper.tcp_offset;
        for (k, s) in [1.0, -1.0].into_iter().enumerate() {
            let y = s * (opening / 2.0 + g.finger_thickness / 2.0);
            let p = Isometry3::translation(tcp, y, 0.0);
            let p = match &self.arm.flange {
                Some(f) => f * p,
                None => p,
            };
            if let Some(c) = world.colliders.get_mut(self.bodies.fingers[k]) {
                c.set_position_wrt_parent(iso_to_pose(&p));
            }
        }
    }

    /// One physics substep's worth of commands: base velocities, arm targets, finger gap. Returns
    /// the base pose predicted for the end of the substep (where the links were placed).
    pub fn command(
        &self,
        world: &mut PhysicsWorld,
        state: &mut RobotState,
        params: &RmpParams,
        cmd: &RobotCommand,
        dt: f64,
    ) -> Isometry3<f64> {
        let b = &self.desc.base;
        let step = |cur: f64, want: f64, acc: f64, max: f64| {
            let want = want.clamp(-max, max);
            cur + (want - cur).clamp(-acc * dt, acc * dt)
        };
        state.v = step(state.v, cmd.v, b.acc_v, b.max_v);
        state.omega = step(state.omega, cmd.omega, b.acc_omega, b.max_omega);
        let iso = self.hold_planar(world);
        let yaw = yaw_of(&iso.rotation);
        // Driven in the floor plane only: a drive velocity along a tilted heading would push the
        // base into the floor, where a contact whose normal lies along the locked height axis
        // makes the solver fling the base metres away.
        let fwd = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
        let body = &mut world.bodies[self.bodies.base];
        body.set_linvel(vec_to_glam(&(fwd * state.v)), true);
        body.set_angvel(vec_to_glam(&Vector3::new(0.0, 0.0, state.omega)), true);

        // The leaf keeps links off fixed geometry; it does not pull a link out of it (an arm
        // stopped with a finger in a shelf board stays stuck if its links are pushed as well).
        let near = match state.arm_blocked {
            true => Vec::new(),
            false => clearance::near_points(&self.arm, &self.bodies.arm_colliders, world, &iso, &state.arm.q),
        };
        let qdd = rmp::resolve(&self.arm, params, &state.arm, &self.home, &cmd.ee_target, &near);
        state.arm = rmp::integrate(&self.arm, &state.arm, &qdd, dt);
        let g = &self.desc.gripper;
        let want = cmd.opening.clamp(0.0, 1.0) * g.max_opening;
        let want = want.max(cmd.min_opening);
        state.opening += (want - state.opening).clamp(-g.opening_speed * dt, g.opening_speed * dt);

        // Links go where the base will be at the end of this substep.
        let (x, y) = (iso.translation.x, iso.translation.y);
        let next = planar(
            x + fwd.x * state.v * dt,
            y + fwd.y * state.v * dt,
            0.0,
            yaw + state.omega * dt,
        );
        // Both modes servo the same links; only the fingers differ.
        self.place_links(world, &next, &state.arm.q, dt);
        match &self.bodies.articulation {
            Some(art) => self.drive_fingers(world, art, state),
            None => self.place_fingers(world, state.opening),
        }
        next
    }

    /// Put the base back on the floor plane (height 0, no roll or pitch) when solver round-off
    /// has moved it off; returns the planar pose.
    ///
    /// Locked axes stop the solver from moving the base along them, but round-off in the
    /// rotation integration still tilts it by ~1e-8 rad per step, and the drift accumulates over
    /// a long episode until the base touches the floor and is flung away (the contact's normal
    /// lies along a locked axis, so the solver's correction becomes unbounded).
    fn hold_planar(&self, world: &mut PhysicsWorld) -> Isometry3<f64> {
        let iso = self.base_iso(world);
        let planar_iso = planar(iso.translation.x, iso.translation.y, 0.0, yaw_of(&iso.rotation));
        let off = iso.translation.z.abs() + iso.rotation.angle_to(&planar_iso.rotation);
        if off > PLANAR_TOLERANCE {
            let body = &mut world.bodies[self.bodies.base];
            body.set_position(iso_to_pose(&planar_iso), false);
            let w = body.angvel();
            body.set_angvel(vec_to_glam(&Vector3::new(0.0, 0.0, f64::from(w.z))), false);
        }
        planar_iso
    }

    /// Servo every link to its pose from the joint targets at the end of the substep.
    fn place_links(&self, world: &mut PhysicsWorld, base: &Isometry3<f64>, q: &JointVec, dt: f64) {
        let fk = self.arm.forward(q);
        for (i, h) in self.bodies.links.iter().enumerate() {
            let target = base * fk.joints[i];
            let body = &mut world.bodies[*h];
            let now = pose_to_iso(body.position());
            let v = (target.translation.vector - now.translation.vector) / dt;
            let w = (target.rotation * now.rotation.inverse()).scaled_axis() / dt;
            body.set_linvel(vec_to_glam(&v), true);
            body.set_angvel(vec_to_glam(&w), true);
        }
    }

    /// After a substep: every robot part touching fixed geometry as `(part, depth)`; a part that
    /// dug in deeper than a few millimetres sends the arm back to its last safe joint targets.
    ///
    /// A shape query rather than the narrow phase's pairs, so the depth is that of the targets just
    /// placed and a grazing touch is still reported.
    pub fn enforce_obstacles(&self, world: &PhysicsWorld, state: &mut RobotState) -> Vec<(u32, f64)> {
        let filter = QueryFilter::only_fixed().predicate(&is_static);
        let dispatcher = world.narrow_phase.query_dispatcher();
        let mut touches = Vec::new();
        // Check where the joint targets put each collider (the dynamic links themselves are held
        // at the surface by the solver, the targets are what must not wind into it).
        let base = self.base_iso(world);
        let fk = self.arm.forward(&state.arm.q);
        for (h, link) in &self.bodies.arm_colliders {
            let co = &world.colliders[*h];
            let pose = iso_to_pose(&placed(co, &base, &fk, *link));
            let part = Tag::unpack(co.user_data).index;
            for (_, other) in world.intersect_shape(pose, co.shape(), filter) {
                let pos12 = pose.inv_mul(other.position());
                let depth = dispatcher
                    .contact(&pos12, co.shape(), other.shape(), 0.0)
                    .ok()
                    .flatten()
                    .map_or(0.0, |c| -c.dist);
                touches.push((part, f64::from(depth.max(0.0))));
            }
        }
        let blocked = touches.iter().any(|(_, d)| *d > STOP_PENETRATION);
        state.arm_blocked = blocked;
        if blocked {
            state.arm.q = state.safe_q;
            state.arm.qd = JointVec::zeros();
        } else {
            state.safe_q = state.arm.q;
        }
        touches
    }

    /// TCP pose in the world: where the joint targets put it, or in the physical grasp mode
    /// where the hand, the fingers' multibody root, really is.
    pub fn tcp_world(&self, world: &PhysicsWorld, state: &RobotState) -> Isometry3<f64> {
        if self.bodies.articulation.is_some() {
            return self.measured_tcp(world);
        }
        self.base_iso(world) * self.arm.forward(&state.arm.q).tcp
    }
}

/// What the robot is told to do during one substep.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotCommand {
    pub v: f64,
    pub omega: f64,
    /// TCP target in the base frame.
    pub ee_target: Isometry3<f64>,
    /// Gripper command in [0, 1].
    pub opening: f64,
    /// The fingers stop at this gap (m): the width of a held object.
    pub min_opening: f64,
}
