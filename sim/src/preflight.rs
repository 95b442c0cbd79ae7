//! Preflight collider check (paper, Monitoring Module): before an episode runs, every key object
//! must have a usable collider, or grasps would fail silently.

use rapier3d::prelude::*;

use crate::bodies::ObjectBody;
use crate::error::SimError;
use crate::material::{Owner, Tag};

/// Every key object has an enabled, solid, finite collider with positive volume and mass that
/// collides with the furniture and encloses the object's centre in its bounding box.
pub fn check(world: &PhysicsWorld, objects: &[ObjectBody]) -> Result<(), SimError> {
    for o in objects {
        let fail = |why: &str| Err(SimError::Preflight(format!("key object {:?}: {why}", o.name)));
        let Some(body) = world.bodies.get(o.body) else {
            return fail("has no rigid body");
        };
        if !body.is_dynamic() || body.mass().is_nan() || body.mass() <= 0.0 {
            return fail("is not a dynamic body with positive mass");
        }
        let colliders = body.colliders();
        if colliders.is_empty() {
            return fail("has no collider");
        }
        let mut aabb: Option<Aabb> = None;
        for h in colliders {
            let c = &world.colliders[*h];
            let tag = Tag::unpack(c.user_data);
            let statics = Owner::Static.groups(false);
            if !c.is_enabled()
                || c.is_sensor()
                || tag.owner != Owner::KeyObject
                || !c.collision_groups().test(statics)
            {
                return fail("has a disabled, sensor or mis-grouped collider");
            }
            if c.volume().is_nan() || c.volume() <= 0.0 || !c.position().is_finite() {
                return fail("has a degenerate collider");
            }
            let b = c.compute_aabb();
            aabb = Some(aabb.map_or(b, |a| a.merged(&b)));
        }
        let centre = body.translation();
        if !aabb.is_some_and(|a| a.contains_local_point(centre)) {
            return fail("its colliders do not enclose its centre");
        }
    }
    Ok(())
}
