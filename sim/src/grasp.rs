//! Grasping: an object whose grasp point (or centre) lies between the closing fingers is
//! attached rigidly to the TCP; opening the gripper releases it to physics.

use nalgebra::{Isometry3, Point3};
use rapier3d::prelude::*;

use crate::convert::{iso_to_pose, pose_to_iso};
use crate::material::Owner;
use crate::sim::{Held, Sim};

/// Make `body` a carried (kinematic, robot-ignoring, furniture-reporting) object, or release it
/// back to physics.
fn set_carried(world: &mut PhysicsWorld, body: RigidBodyHandle, carried: bool) {
    let (kind, groups, types) = if carried {
        (
            RigidBodyType::KinematicPositionBased,
            Owner::KeyObject.held_groups(),
            ActiveCollisionTypes::default() | ActiveCollisionTypes::KINEMATIC_FIXED,
        )
    } else {
        (
            RigidBodyType::Dynamic,
            Owner::KeyObject.groups(false),
            ActiveCollisionTypes::default(),
        )
    };
    world.bodies[body].set_body_type(kind, true);
    let handles: Vec<ColliderHandle> = world.bodies[body].colliders().to_vec();
    for c in handles {
        if let Some(co) = world.colliders.get_mut(c) {
            co.set_collision_groups(groups);
            co.set_active_collision_types(types);
        }
    }
}

impl Sim {
    /// Attach an object whose grasp point (or centre) is between the closing fingers; release on open.
    pub(crate) fn update_grasp(&mut self, g: f64) {
        let grip = &self.robot.desc.gripper;
        if let Some(h) = self.dynamic.held {
            if g > grip.release_threshold {
                set_carried(&mut self.world, self.objects[h.object].body, false);
                self.dynamic.held = None;
            }
            return;
        }
        let opening = self.dynamic.robot.opening;
        if g >= grip.grasp_threshold || opening < 0.01 {
            return;
        }
        let tcp = self.robot.tcp_world(&self.world, &self.dynamic.robot);
        let inside = |p: Point3<f64>| {
            let l = tcp.inverse_transform_point(&p);
            l.x.abs() <= grip.finger_length / 2.0 + 0.01
                && l.y.abs() <= opening / 2.0
                && l.z.abs() <= grip.finger_height / 2.0 + 0.015
        };
        let found = self.objects.iter().position(|o| {
            let pose = pose_to_iso(self.world.bodies[o.body].position());
            inside(pose * Point3::from(o.grasp_offset)) || inside(pose * Point3::origin())
        });
        if let Some(i) = found {
            let body = self.objects[i].body;
            let obj_pose = pose_to_iso(self.world.bodies[body].position());
            let offset = tcp.inverse() * obj_pose;
            // Rigid attachment: the object becomes a kinematic body carried at its grasp offset from
            // the TCP (a fixed joint to the ideal position-controlled wrist). rapier's islands reject
            // joints anchored on kinematic links, and a joint to the base would lag the wrist.
            set_carried(&mut self.world, body, true);
            self.dynamic.held = Some(Held {
                object: i,
                width: opening,
                offset,
            });
        }
    }

    /// Move the held object with the TCP to where the links go this substep.
    pub(crate) fn carry(&mut self, next_base: &Isometry3<f64>) {
        let Some(h) = self.dynamic.held else { return };
        let pose = next_base * self.robot.arm.forward(&self.dynamic.robot.arm.q).tcp * h.offset;
        let body = self.objects[h.object].body;
        self.world.bodies[body].set_next_kinematic_position(iso_to_pose(&pose));
    }
}
