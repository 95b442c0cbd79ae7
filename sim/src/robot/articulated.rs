//! The physical grasp mode's arm (docs/twin/robot.md): the arm as a rapier multibody whose revolute
//! joints are driven by motors from the RMP controller's integrated targets, and a parallel gripper
//! whose fingers are prismatic joints with force-limited motors, so only friction holds an object.
//!
//! Like the paper's articulation controller: RMPflow's joint accelerations are integrated into
//! position and velocity targets (`rmp.rs`, unchanged) and each joint's motor servos to them
//! (stiffness, damping, the description's effort limit as its maximum torque). The links carry
//! no gravity (an ideal gravity compensation, as an articulation controller applies), so the
//! motors' torque goes to following the targets and carrying the load.
//!
//! The multibody's root is a weightless mount body fixed to the base by an impulse joint: the
//! base stays the velocity-driven body it is in the abstract mode, and the arm moves with it at
//! the base's velocity (contacts and friction in the hand see the motion, a kinematic root would
//! teleport the hand under a held object).

use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;

use super::desc::RobotDesc;
use super::{FINGERS, Robot, RobotState, collider, links};
use crate::config::ArticulationConfig;
use crate::convert::{iso_to_pose, pose_to_iso, vec_to_glam};
use crate::material::{Material, Materials, Owner};

/// Mass of an arm link whose description gives none (kg): a ViperX-300-class link's.
const DEFAULT_LINK_MASS: f64 = 0.5;
/// Mass of the mount body between the base and the waist (kg).
const MOUNT_MASS: f32 = 0.5;

/// Handles of the articulated arm.
#[derive(Debug, Clone)]
pub struct Articulation {
    pub mount: RigidBodyHandle,
    pub joints: Vec<MultibodyJointHandle>,
    /// Finger bodies (left, right) and their prismatic joints.
    pub finger_bodies: [RigidBodyHandle; 2],
    pub finger_joints: [MultibodyJointHandle; 2],
    pub config: ArticulationConfig,
}

/// Extra travel of each finger beyond the description's opening at the same command (m): the
/// abstract gripper's opening is sized to a grasp volume; a physical descent also needs room
/// around the object for the hand's tracking error.
const OPEN_MARGIN: f64 = 0.01;

fn finger_travel(desc: &RobotDesc, opening: f64) -> f32 {
    let margin = OPEN_MARGIN * opening / desc.gripper.max_opening;
    (opening / 2.0 + margin + desc.gripper.finger_thickness / 2.0) as f32
}

/// The fingers' servo target at `opening`: the travel less `preload` in proportion as the gripper
/// closes (none at `max_opening`, all of it closed), so an object thinner than the servo needs to
/// build its squeeze is held as hard as a thick one ([`ArticulationConfig::finger_preload`]).
fn finger_target(desc: &RobotDesc, opening: f64, preload: f64) -> f32 {
    let closing = 1.0 - (opening / desc.gripper.max_opening).clamp(0.0, 1.0);
    finger_travel(desc, opening) - (preload * closing) as f32
}

impl Robot {
    /// The robot of the physical grasp mode: the base as in [`Robot::spawn`], the arm as a
    /// motor-driven multibody at the home configuration, the fingers on prismatic joints.
    pub fn spawn_articulated(
        world: &mut PhysicsWorld,
        mats: &mut Materials,
        desc: &RobotDesc,
        start: [f64; 3],
        config: &ArticulationConfig,
    ) -> (Robot, RobotState) {
        let (mut robot, state) = Robot::spawn(world, mats, desc, start);
        // The abstract arm's links and fingers make way for the articulated ones.
        for h in std::mem::take(&mut robot.bodies.links) {
            world.remove_body(h);
        }
        let p = &mut world.integration_parameters;
        p.contact_softness.natural_frequency = config.contact_frequency as f32;
        p.static_contact_softness.natural_frequency = 2.0 * config.contact_frequency as f32;
        // The multibody's mass matrix is rebuilt and factorised at every solver substep (about
        // 25 µs each for this arm), so the physical mode solves in fewer substeps with more
        // constraint iterations each (docs/twin/robot.md has the figures).
        p.num_solver_iterations = config.solver_iterations as usize;
        p.num_internal_pgs_iterations = config.pgs_iterations as usize;

        let base_iso = robot.base_iso(world);
        let fk = robot.arm.forward(&state.arm.q);
        let mount = world.insert_body(
            RigidBodyBuilder::dynamic()
                .pose(iso_to_pose(&base_iso))
                .additional_mass(MOUNT_MASS)
                .gravity_scale(0.0)
                .can_sleep(false),
        );
        world.insert_impulse_joint(robot.bodies.base, mount, FixedJointBuilder::new());
        let arm_mat = mats.add(Material::plain(desc.arm.color));
        let grip_mat = mats.add(Material::plain(desc.gripper.color));
        let g = &desc.gripper;
        let mut arm_colliders = Vec::new();
        let mut parent = mount;
        let mut joints = Vec::new();
        let dof = robot.arm.dof;
        let mut links = Vec::new();
        for i in 0..dof {
            let mass = desc.arm.joints[i].mass.unwrap_or(DEFAULT_LINK_MASS);
            let link = links::link_colliders(desc, &robot.arm, i, arm_mat, mats);
            let body = RigidBodyBuilder::dynamic()
                .pose(iso_to_pose(&(base_iso * fk.joints[i])))
                .gravity_scale(0.0)
                .can_sleep(false);
            // A link without shapes carries its mass on the body.
            let body = if link.is_empty() {
                body.additional_mass(mass as f32)
            } else {
                body
            };
            let h = world.insert_body(body);
            let each = mass as f32 / link.len() as f32;
            for co in link {
                arm_colliders.push((world.insert_collider(co.mass(each), Some(h)), i));
            }
            if i == dof - 1 {
                let palm = links::palm(desc, &robot.arm, grip_mat).mass(0.1);
                arm_colliders.push((world.insert_collider(palm, Some(h)), i));
            }
            let anchor = if i == 0 {
                robot.arm.mount + robot.arm.origins[0]
            } else {
                robot.arm.origins[i]
            };
            let lim = [robot.arm.lower[i] as f32, robot.arm.upper[i] as f32];
            let mut joint = RevoluteJointBuilder::new(vec_to_glam(&robot.arm.axes[i]))
                .local_anchor1(vec_to_glam(&anchor))
                .limits(lim)
                .motor_position(
                    state.arm.q[i] as f32,
                    config.joint_stiffness as f32,
                    config.joint_damping as f32,
                )
                .motor_max_force(desc.arm.joints[i].effort as f32)
                .build();
            let mount = if i == 0 { robot.arm.mount_rotation } else { None };
            let fixed = match (mount, robot.arm.rotations[i]) {
                (Some(m), Some(r)) => Some(m * r),
                (m, r) => m.or(r),
            };
            if let Some(fixed) = fixed {
                // A turned joint frame: the parent's joint frame is the child's turned by it.
                let f2 = pose_to_iso(&joint.data.local_frame2);
                let f1 = Isometry3::from_parts(nalgebra::Translation3::from(anchor), fixed * f2.rotation);
                joint.data.set_local_frame1(iso_to_pose(&f1));
            }
            let handle = world
                .insert_multibody_joint(parent, h, joint)
                .expect("a chain of new bodies is a valid multibody");
            set_coordinate(world, handle, state.arm.q[i] as f32);
            joints.push(handle);
            parent = h;
            links.push(h);
        }
        let last = links[dof - 1];
        let tcp = Isometry3::translation(g.tcp_offset, 0.0, 0.0);
        let travel = finger_travel(desc, state.opening);
        let lim = [finger_travel(desc, 0.0), finger_travel(desc, g.max_opening)];
        let mut finger_bodies = [last; 2];
        let mut finger_joints = Vec::new();
        for (k, s) in [1.0f64, -1.0].into_iter().enumerate() {
            let axis = Vector3::y() * s;
            let pose = base_iso * fk.hand * tcp * nalgebra::Translation3::from(axis * f64::from(travel));
            let body = world.insert_body(
                RigidBodyBuilder::dynamic()
                    .pose(iso_to_pose(&pose))
                    .gravity_scale(0.0)
                    .can_sleep(false),
            );
            let fs = [g.finger_length, g.finger_thickness, g.finger_height].map(|v| v as f32 / 2.0);
            let co = collider(
                SharedShape::cuboid(fs[0], fs[1], fs[2]),
                FINGERS[k],
                grip_mat,
                true,
            )
            .collision_groups(Owner::Robot.physical_finger_groups())
            .friction(config.finger_friction as f32)
            .mass(config.finger_mass as f32);
            robot.bodies.fingers[k] = world.insert_collider(co, Some(body));
            let mut joint = PrismaticJointBuilder::new(vec_to_glam(&axis))
                .local_anchor1(vec_to_glam(&tcp.translation.vector))
                .limits(lim)
                .motor_model(MotorModel::ForceBased)
                .motor_position(
                    travel,
                    config.finger_stiffness as f32,
                    config.finger_damping as f32,
                )
                .motor_max_force(config.finger_force as f32)
                .build();
            if let Some(f) = &robot.arm.flange {
                // A mounted gripper's hand frame is the last link's turned and moved by the
                // flange: the fingers slide along the hand's closing axis from its TCP, as the
                // palm and the finger bodies' spawn poses stand, not the last link's.
                let f2 = pose_to_iso(&joint.data.local_frame2);
                let at = f * tcp;
                let f1 = Isometry3::from_parts(at.translation, at.rotation * f2.rotation);
                joint.data.set_local_frame1(iso_to_pose(&f1));
            }
            let handle = world
                .insert_multibody_joint(last, body, joint)
                .expect("a finger is a new body");
            set_coordinate(world, handle, travel);
            finger_bodies[k] = body;
            finger_joints.push(handle);
        }
        couple_fingers(world, [finger_joints[0], finger_joints[1]]);
        robot.bodies.links = links;
        robot.bodies.arm_colliders = arm_colliders;
        robot.bodies.articulation = Some(Articulation {
            mount,
            joints,
            finger_bodies,
            finger_joints: finger_joints.try_into().expect("two fingers"),
            config: config.clone(),
        });
        (robot, state)
    }

    /// Drive the joint motors to the controller's targets and the fingers to the commanded gap
    /// (one substep; the motors' targets change every substep, so the multibody is woken).
    pub(super) fn drive_joints(&self, world: &mut PhysicsWorld, art: &Articulation, state: &RobotState) {
        let c = &art.config;
        for (i, h) in art.joints.iter().enumerate() {
            let (q, qd) = (state.arm.q[i] as f32, state.arm.qd[i] as f32);
            if let Some((mb, link)) = world.multibody_joints.get_mut(*h)
                && let Some(l) = mb.link_mut(link)
            {
                let (k, d) = (c.joint_stiffness as f32, c.joint_damping as f32);
                l.joint.data.set_motor(JointAxis::AngX, q, qd, k, d);
            }
        }
        let travel = finger_target(&self.desc, state.opening, c.finger_preload);
        for h in &art.finger_joints {
            if let Some((mb, link)) = world.multibody_joints.get_mut(*h)
                && let Some(l) = mb.link_mut(link)
            {
                let (k, d) = (c.finger_stiffness as f32, c.finger_damping as f32);
                l.joint.data.set_motor(JointAxis::LinX, travel, 0.0, k, d);
            }
        }
        world.wake_up(self.bodies.links[0], true);
    }

    /// The measured TCP in the world: the last link's pose (not the targets' forward kinematics).
    pub(super) fn measured_tcp(&self, world: &PhysicsWorld) -> Isometry3<f64> {
        let last = pose_to_iso(world.bodies[self.bodies.links[self.arm.dof - 1]].position());
        let hand = match &self.arm.flange {
            Some(f) => last * f,
            None => last,
        };
        hand * nalgebra::Translation3::new(self.desc.gripper.tcp_offset, 0.0, 0.0)
    }

    /// The measured gap between the fingers' inner faces (m).
    pub fn measured_gap(&self, world: &PhysicsWorld) -> Option<f64> {
        let art = self.bodies.articulation.as_ref()?;
        let tcp = self.measured_tcp(world);
        let [l, r] = art.finger_bodies.map(|b| {
            (tcp.inverse() * pose_to_iso(world.bodies[b].position()))
                .translation
                .vector
        });
        Some(l.y - r.y - self.desc.gripper.finger_thickness)
    }
}

/// Make the fingers move as one, like a parallel gripper's rack and pinion: otherwise two equal
/// force-limited motors squeezing an object leave their common motion free, and the pair drifts
/// sideways until one finger stops at its limit.
fn couple_fingers(world: &mut PhysicsWorld, joints: [MultibodyJointHandle; 2]) {
    let Some([l, r]) = joints
        .iter()
        .map(|h| {
            world
                .multibody_joints
                .get(*h)
                .map(|(mb, id)| mb.link(id).map_or(id, |l| l.link_id()))
        })
        .collect::<Option<Vec<_>>>()
        .and_then(|v| <[usize; 2]>::try_from(v).ok())
    else {
        return;
    };
    if let Some((mb, _)) = world.multibody_joints.get_mut(joints[0]) {
        mb.add_dof_coupling(MultibodyDofCoupling {
            link1: l,
            dof1: 0,
            axis1: 0,
            link2: r,
            dof2: 0,
            axis2: 0,
            coeff: 1.0,
            offset: 0.0,
        });
    }
}

/// Set a one-degree-of-freedom joint's coordinate (at spawn: the multibody starts at zero).
fn set_coordinate(world: &mut PhysicsWorld, h: MultibodyJointHandle, value: f32) {
    if let Some((mb, link)) = world.multibody_joints.get_mut(h)
        && let Some(l) = mb.link_mut(link)
    {
        l.joint.apply_displacement(&[value]);
    }
}
