//! Grasping. Abstract mode: an object whose grasp point (or centre) lies between the closing
//! fingers is carried rigidly at its grasp offset from the TCP; opening the gripper releases it to
//! physics. Physical mode: nothing is attached (friction between the force-limited fingers and the
//! object holds it); an object counts as held when both fingers touch it and it touches nothing
//! but the robot (docs/twin/robot.md).

use nalgebra::{Isometry3, Point3, Vector3};
use rapier3d::prelude::*;

use crate::bodies::Held;
use crate::convert::{pose_to_iso, vec_to_glam};
use crate::material::{Owner, Tag};
use crate::sim::Sim;

/// Speed limits of the grasp servo (m/s, rad/s): a snagged object is not flung.
const MAX_CARRY_SPEED: f64 = 2.0;
const MAX_CARRY_SPIN: f64 = 20.0;
/// A held object this far from its place in the hand has slipped out (m).
const SLIP_DISTANCE: f64 = 0.05;

/// Make `body` a carried object (weightless, ignoring the robot's links) or release it.
///
/// A carried object stays a dynamic body: every substep its velocity is set to bring it to its
/// grasp offset from the TCP (a stiff fixed-joint servo, like the links themselves), so furniture
/// still stops it and releasing it needs nothing but restoring gravity.
fn set_carried(world: &mut PhysicsWorld, body: RigidBodyHandle, carried: bool) {
    let groups = if carried {
        Owner::KeyObject.held_groups()
    } else {
        Owner::KeyObject.groups(false)
    };
    world.bodies[body].set_gravity_scale(if carried { 0.0 } else { 1.0 }, true);
    let handles: Vec<ColliderHandle> = world.bodies[body].colliders().to_vec();
    for c in handles {
        if let Some(co) = world.colliders.get_mut(c) {
            co.set_collision_groups(groups);
        }
    }
}

/// A contact this close (or deeper) counts as touching (m): rapier keeps contacts a little
/// before they touch.
const TOUCH_DISTANCE: f32 = 0.001;

/// Where a collider is now: its body's pose (the collider's own copy is synchronised only at the
/// end of a step) times its offset on the body.
fn collider_pose(world: &PhysicsWorld, co: &Collider) -> Pose {
    match co.parent().and_then(|b| world.bodies.get(b)) {
        Some(body) => *body.position() * co.position_wrt_parent().copied().unwrap_or_default(),
        None => *co.position(),
    }
}

/// Whether colliders `a` and `b` touch, by a contact query at their bodies' current poses.
///
/// Not from the narrow phase's manifolds: with the physical mode's single solver substep a
/// manifold between two moving bodies can keep the distance of an earlier step (a squeezing
/// finger read 15 mm away), while the broad phase's pair list is current.
fn touching(world: &PhysicsWorld, a: &Collider, b: &Collider) -> bool {
    let pos12 = collider_pose(world, a).inv_mul(&collider_pose(world, b));
    world
        .narrow_phase
        .query_dispatcher()
        .contact(&pos12, a.shape(), b.shape(), TOUCH_DISTANCE)
        .ok()
        .flatten()
        .is_some_and(|c| c.dist <= TOUCH_DISTANCE)
}

impl Sim {
    /// Physical mode, after a substep: the held object is the one both fingers touch while it
    /// touches nothing but the robot (lifted off its support).
    pub(crate) fn update_physical_hold(&mut self) {
        self.dynamic.held = self.physical_hold();
    }

    fn physical_hold(&self) -> Option<Held> {
        let found = self
            .objects
            .iter()
            .position(|o| self.pinched_off_its_support(o.body))?;
        let tcp = self.robot.tcp_world(&self.world, &self.dynamic.robot);
        let pose = pose_to_iso(self.world.bodies[self.objects[found].body].position());
        Some(Held {
            object: found,
            width: self.robot.measured_gap(&self.world).unwrap_or(0.0),
            offset: tcp.inverse() * pose,
        })
    }

    /// Both fingers touch `body` and nothing but the robot does. Contact queries cost
    /// microseconds each, so only the broad phase's pairs are queried, the fingers first.
    fn pinched_off_its_support(&self, body: RigidBodyHandle) -> bool {
        let w = &self.world;
        let pairs = || {
            w.bodies[body].colliders().iter().flat_map(move |c| {
                w.contact_pairs_with(*c).map(move |p| {
                    let other = if p.collider1 == *c {
                        p.collider2
                    } else {
                        p.collider1
                    };
                    (*c, other)
                })
            })
        };
        let touch = |(a, b): (ColliderHandle, ColliderHandle)| match (w.colliders.get(a), w.colliders.get(b))
        {
            (Some(a), Some(b)) => touching(w, a, b),
            _ => false,
        };
        let robot = |h: ColliderHandle| {
            w.colliders
                .get(h)
                .is_some_and(|co| Tag::unpack(co.user_data).owner == Owner::Robot)
        };
        self.robot
            .bodies
            .fingers
            .iter()
            .all(|f| pairs().any(|(c, o)| o == *f && touch((c, o))))
            && !pairs().any(|(c, o)| !robot(o) && touch((c, o)))
    }

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
            // Rigid attachment at the grasp offset from the TCP (see `set_carried`).
            set_carried(&mut self.world, body, true);
            self.dynamic.held = Some(Held {
                object: i,
                width: opening,
                offset,
            });
        }
    }

    /// Servo the held object to its place in the hand at the end of this substep; drop it when
    /// something holds it back too far.
    pub(crate) fn carry(&mut self, next_base: &Isometry3<f64>, dt: f64) {
        let Some(h) = self.dynamic.held else { return };
        let target = next_base * self.robot.arm.forward(&self.dynamic.robot.arm.q).tcp * h.offset;
        let body = self.objects[h.object].body;
        let now = pose_to_iso(self.world.bodies[body].position());
        let dp = target.translation.vector - now.translation.vector;
        if dp.norm() > SLIP_DISTANCE {
            set_carried(&mut self.world, body, false);
            self.dynamic.held = None;
            return;
        }
        let cap = |v: Vector3<f64>, max: f64| if v.norm() > max { v * (max / v.norm()) } else { v };
        let v = cap(dp / dt, MAX_CARRY_SPEED);
        let w = cap(
            (target.rotation * now.rotation.inverse()).scaled_axis() / dt,
            MAX_CARRY_SPIN,
        );
        let rb = &mut self.world.bodies[body];
        rb.set_linvel(vec_to_glam(&v), true);
        rb.set_angvel(vec_to_glam(&w), true);
    }
}
