//! The obstacle leaf of a seven-joint arm's controller (RMPflow's collision avoidance): the point
//! of each link nearest fixed geometry, once within [`RANGE`] of it, is pushed straight away.
//!
//! Only a redundant arm gets it. Its self-motion (the elbow turning about the shoulder–wrist
//! line) can take a link off a shelf board while the tool stays on its target: the Panda's
//! forearm, reaching under a board for a fork at the back of a shelf, met the board's front edge
//! and the arm stopped there (a link that digs in reverts the arm, `Robot::enforce_obstacles`).
//! A six-joint arm has no such freedom: the leaf could only pull its tool off the target, so it
//! is left out and a six-joint arm's control is exactly what it was. The hand (the last link,
//! with the palm and fingers) and the wrist link before it are left out too: where they go is the
//! target's business. The leaf keeps links off; it does not pull one out (`Robot::command` leaves
//! it out while the arm is stopped: pushing the links of a Kinova3 stopped with a finger in a
//! shelf board kept it there for the rest of the episode).

use nalgebra::{Isometry3, SMatrix, Vector3};
use rapier3d::prelude::*;

use super::kinematics::{ArmFk, ArmModel, JointVec, MAX_DOF};
use super::obstacles::{is_static, placed};
use crate::convert::{iso_to_pose, pose_to_iso, vec_from_glam};

/// Within this distance of fixed geometry a link is pushed away, m.
pub const RANGE: f64 = 0.05;
/// The push at contact, m/s² (it grows linearly from zero at [`RANGE`]).
const GAIN: f64 = 20.0;
/// Damping of the approach speed, 1/s (a link moving away is not held back).
const DAMPING: f64 = 10.0;
/// The leaf's metric at contact (the tool's position attractor weighs 1); it grows
/// quadratically from zero at [`RANGE`].
const WEIGHT: f64 = 1.0;

/// A link's point near fixed geometry, in the arm's base frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Near {
    /// The link (0-based joint index) the point moves with.
    pub link: usize,
    pub point: Vector3<f64>,
    /// Unit normal pointing away from the geometry.
    pub away: Vector3<f64>,
    /// Distance to the geometry, m (negative inside it).
    pub distance: f64,
}

/// Each arm collider's nearest point within [`RANGE`] of fixed geometry, the hand's and the
/// wrist link's before it excepted, with the links where joint values `q` put them on a base at
/// `base`. Empty for an arm of six joints or fewer.
pub(super) fn near_points(
    arm: &ArmModel,
    colliders: &[(ColliderHandle, usize)],
    world: &PhysicsWorld,
    base: &Isometry3<f64>,
    q: &JointVec,
) -> Vec<Near> {
    if arm.dof <= 6 {
        return Vec::new();
    }
    let filter = QueryFilter::only_fixed().predicate(&is_static);
    let dispatcher = world.narrow_phase.query_dispatcher();
    let fk = arm.forward(q);
    let to_base = base.inverse();
    let mut out = Vec::new();
    for (h, link) in colliders.iter().filter(|(_, l)| *l + 2 < arm.dof) {
        let co = &world.colliders[*h];
        let iso = placed(co, base, &fk, *link);
        let pose = iso_to_pose(&iso);
        let aabb = co.shape().compute_aabb(&pose).loosened(RANGE as f32);
        let mut nearest: Option<Near> = None;
        for (_, other) in world.intersect_aabb_conservative(aabb, filter) {
            let pos12 = pose.inv_mul(other.position());
            let Ok(Some(c)) = dispatcher.contact(&pos12, co.shape(), other.shape(), RANGE as f32) else {
                continue;
            };
            let distance = f64::from(c.dist);
            if distance > RANGE || nearest.is_some_and(|n| n.distance <= distance) {
                continue;
            }
            // The contact in the collider's frame as f32 placed it (`pose`), so the point lies
            // on the shape the query saw.
            let p = pose_to_iso(&pose) * nalgebra::Point3::from(vec_from_glam(c.point1));
            let n1 = iso.rotation * vec_from_glam(c.normal1);
            nearest = Some(Near {
                link: *link,
                point: (to_base * p).coords,
                away: to_base.rotation * -n1,
                distance,
            });
        }
        out.extend(nearest);
    }
    out
}

/// The leaf of `near` as `(Jacobian row, metric, desired acceleration)` along its normal.
pub(super) fn leaf(
    arm: &ArmModel,
    fk: &ArmFk,
    qd: &JointVec,
    near: &Near,
) -> (SMatrix<f64, 1, MAX_DOF>, f64, f64) {
    let jac = arm.point_jacobian(fk, near.link, &near.point);
    let row = SMatrix::<f64, 1, MAX_DOF>::from_fn(|_, i| near.away.dot(&jac.fixed_view::<3, 1>(0, i)));
    let closeness = (1.0 - near.distance / RANGE).clamp(0.0, 2.0);
    let speed = (row * qd)[0];
    let accel = GAIN * closeness - DAMPING * speed.min(0.0);
    (row, WEIGHT * closeness * closeness, accel)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::desc::RobotDesc;

    /// The leaf's row is the rate of the point's distance along its normal: finite differences of
    /// the point carried by its link agree, and joints past the link do not move it.
    #[test]
    fn the_leaf_row_is_the_points_speed_along_its_normal() {
        let desc = RobotDesc::load_default().unwrap();
        let arm = ArmModel::new(&desc);
        let q = arm.vec(&[0.3, -0.2, 0.8, 0.4, 0.6, -0.5]);
        let fk = arm.forward(&q);
        let link = 3;
        let local = Vector3::new(0.02, -0.03, 0.05);
        let point = (fk.joints[link] * nalgebra::Point3::from(local)).coords;
        let away = Vector3::new(0.3, -0.5, 0.8).normalize();
        let near = Near {
            link,
            point,
            away,
            distance: 0.01,
        };
        let (row, m, a) = leaf(&arm, &fk, &JointVec::zeros(), &near);
        let h = 1e-6;
        for i in 0..arm.dof {
            let mut q2 = q;
            q2[i] += h;
            let p2 = (arm.forward(&q2).joints[link] * nalgebra::Point3::from(local)).coords;
            let rate = away.dot(&(p2 - point)) / h;
            assert!(
                (rate - row[i]).abs() < 1e-4,
                "joint {i}: {rate} against {}",
                row[i]
            );
        }
        // 1 cm inside the 5 cm range: four fifths of the push, the metric its square.
        assert!((a - GAIN * 0.8).abs() < 1e-12 && (m - WEIGHT * 0.64).abs() < 1e-12);
        let (_, m_far, a_far) = leaf(
            &arm,
            &fk,
            &JointVec::zeros(),
            &Near {
                distance: RANGE,
                ..near
            },
        );
        assert_eq!((m_far, a_far), (0.0, 0.0));
    }
}
