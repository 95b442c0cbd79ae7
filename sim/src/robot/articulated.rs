//! The physical grasp mode's gripper (docs/twin/robot.md): a parallel gripper whose fingers are
//! prismatic joints with force-limited motors, so only friction holds an object.
//!
//! The arm's links are the abstract mode's: RMPflow's joint accelerations are integrated into
//! position targets (`rmp.rs`, unchanged) and each link's velocity is set every substep to reach
//! its pose from them (an ideal position-controlled arm, as the paper's articulation controller
//! gives with gravity compensation). The fingers are a small rapier multibody whose root is the
//! hand, the last link: its six root coordinates move at the velocity the link servo gives the
//! hand, so the fingers carry the base's and the arm's motion into their contacts (a kinematic
//! root would teleport them under a held object), and only the two finger joints are solved
//! for. The arm as a multibody of its own (until 2026-11-30: 14 degrees of freedom with the
//! base's mount, the mass matrix rebuilt every solver substep) cost two thirds of the physical
//! step; this hand carries the held object the same way (docs/twin/robot.md has both figures).

use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;

use super::desc::RobotDesc;
use super::{FINGERS, Robot, RobotState, collider};
use crate::config::ArticulationConfig;
use crate::convert::{iso_to_pose, pose_to_iso, vec_to_glam};
use crate::material::{Material, Materials, Owner};

/// Mass of the hand, the fingers' multibody root (kg). Its velocity is set every substep, so
/// the mass only weighs what a held object's contacts do to it within one: with 100 kg the
/// solver converged so poorly against the 0.06 kg fingers that held apples were pushed out of
/// the grip (dev places 86/204).
const HAND_MASS: f32 = 2.0;

/// Handles of the physical gripper.
#[derive(Debug, Clone)]
pub struct Articulation {
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
    /// The robot of the physical grasp mode: the base and the arm as in [`Robot::spawn`], the
    /// fingers on force-limited prismatic joints of a multibody rooted at the hand.
    pub fn spawn_articulated(
        world: &mut PhysicsWorld,
        mats: &mut Materials,
        desc: &RobotDesc,
        start: [f64; 3],
        config: &ArticulationConfig,
    ) -> (Robot, RobotState) {
        let (mut robot, state) = Robot::spawn(world, mats, desc, start);
        // The abstract hand's fingers make way for force-limited ones.
        for h in robot.bodies.fingers {
            world.remove_collider(h);
        }
        let fingers = robot.bodies.fingers;
        robot.bodies.arm_colliders.retain(|(h, _)| !fingers.contains(h));
        let p = &mut world.integration_parameters;
        p.contact_softness.natural_frequency = config.contact_frequency as f32;
        p.static_contact_softness.natural_frequency = 2.0 * config.contact_frequency as f32;
        p.num_solver_iterations = config.solver_iterations as usize;
        p.num_internal_pgs_iterations = config.pgs_iterations as usize;

        let base_iso = robot.base_iso(world);
        let fk = robot.arm.forward(&state.arm.q);
        let grip_mat = mats.add(Material::plain(desc.gripper.color));
        let g = &desc.gripper;
        let last = robot.hand();
        // The hand's mass sits at its origin, where the multibody's root velocity is taken (its
        // colliders weigh nothing), and it keeps the default dominance: a held object pressed
        // against the palm or the wrist meets the hand's mass, not an unstoppable link that
        // wrenches it out of the fingers (dev places of cups: 56/93 failed with the links'
        // dominance, 1/93 without).
        for co in world.bodies[last].colliders().to_vec() {
            if let Some(c) = world.colliders.get_mut(co) {
                c.set_density(0.0);
            }
        }
        let hand_mass = MassProperties::new(Vector::ZERO, HAND_MASS, Vector::splat(HAND_MASS * 0.01));
        let hand = &mut world.bodies[last];
        hand.set_additional_mass_properties(hand_mass, true);
        hand.set_dominance_group(0);
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
        robot.bodies.articulation = Some(Articulation {
            finger_bodies,
            finger_joints: finger_joints.try_into().expect("two fingers"),
            config: config.clone(),
        });
        (robot, state)
    }

    /// Move the fingers' root with the hand and drive the fingers to the commanded gap (one
    /// substep, after `place_links` has set the hand's velocity; the motors' targets change every
    /// substep, so the multibody is woken).
    pub(super) fn drive_fingers(&self, world: &mut PhysicsWorld, art: &Articulation, state: &RobotState) {
        let c = &art.config;
        // The root's generalized velocity is the multibody's state (rapier writes it over the
        // body's): the hand's linear velocity at its origin, where its mass sits, and its angular
        // velocity, both in the world frame.
        let hand = self.hand();
        let vels = *world.bodies[hand].vels();
        if let Some((mb, _)) = world.multibody_joints.get_mut(art.finger_joints[0]) {
            let mut v = mb.generalized_velocity_mut();
            for k in 0..3 {
                v[k] = vels.linvel[k];
                v[3 + k] = vels.angvel[k];
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
        world.wake_up(hand, true);
    }

    /// The hand: the arm's last link, the fingers' multibody root.
    fn hand(&self) -> RigidBodyHandle {
        self.bodies.links[self.arm.dof - 1]
    }

    /// The measured TCP in the world: the hand's pose (where the link servo put it, not the
    /// targets' forward kinematics).
    pub(super) fn measured_tcp(&self, world: &PhysicsWorld) -> Isometry3<f64> {
        let last = pose_to_iso(world.bodies[self.hand()].position());
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
