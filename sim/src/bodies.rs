//! The key objects' rigid bodies and the gripper's hold on one: what the simulator, its grasp
//! and its pre-flight check all read, so it is none of theirs.

use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;

/// A key object in the world.
#[derive(Debug, Clone)]
pub struct ObjectBody {
    pub name: String,
    pub body: RigidBodyHandle,
    pub half_height: f64,
    /// Grasp point from the centre, object frame.
    pub grasp_offset: Vector3<f64>,
}

/// The gripper's hold on an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Held {
    pub object: usize,
    /// Finger gap when the grasp closed (m).
    pub width: f64,
    /// Object pose in the TCP frame at the grasp.
    pub offset: Isometry3<f64>,
}

/// Set the collision groups of every collider of `body`.
pub(crate) fn set_groups(world: &mut PhysicsWorld, body: RigidBodyHandle, groups: InteractionGroups) {
    let handles: Vec<ColliderHandle> = world.bodies[body].colliders().to_vec();
    for c in handles {
        if let Some(co) = world.colliders.get_mut(c) {
            co.set_collision_groups(groups);
        }
    }
}
