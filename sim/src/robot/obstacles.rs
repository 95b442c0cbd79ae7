//! Where the arm's colliders stand against the scene's fixed geometry, for the two queries that
//! need it: the stop of a link dug into furniture (`Robot::enforce_obstacles`) and a seven-joint
//! arm's obstacle leaf (`clearance`). Both place the colliders where the joint targets put them,
//! not where the link bodies are.

use nalgebra::Isometry3;
use rapier3d::prelude::*;

use super::kinematics::ArmFk;
use crate::convert::pose_to_iso;
use crate::material::{Owner, Tag};

/// Fixed geometry of the scene (furniture, walls), as the arm's obstacle queries filter it.
pub(super) fn is_static(_: ColliderHandle, c: &Collider) -> bool {
    Tag::unpack(c.user_data).owner == Owner::Static
}

/// Where arm collider `co`, on joint `link`'s frame, stands with the joints at `fk` on a base at
/// `base` (world frame): the joint targets' placement, not the link body's.
pub(super) fn placed(co: &Collider, base: &Isometry3<f64>, fk: &ArmFk, link: usize) -> Isometry3<f64> {
    let local = co
        .position_wrt_parent()
        .map_or(Isometry3::identity(), pose_to_iso);
    base * fk.joints[link] * local
}
