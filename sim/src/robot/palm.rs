//! How far the hand's own geometry (the palm box and a description's hand meshes, fingers
//! excepted) stays behind the tool centre point along the approach axis: the room a grasp has
//! between the TCP and the palm. The oracle keeps a round object's top out of that room in the
//! physical grasp mode (`episode/src/oracle/grasp.rs`): robosuite's Panda hand reaches 3.1 cm
//! behind its grip site against the shipped hand's 4.0 cm (its wrist capsule's rounded end),
//! and an apple grasped at its centre was pressed into the counter by the palm, the fingers
//! stopping short of it (the Panda lost 25 of the dev split's 62 apple picks).

use nalgebra::{Isometry3, Translation3, Vector3};
use rapier3d::prelude::*;

use super::desc::RobotDesc;
use super::kinematics::ArmModel;
use super::links;
use crate::convert::{iso_to_pose, pose_to_iso, vec_to_glam};
use crate::material::Materials;

/// The palm's reach: the least distance (m) from the TCP back along the approach axis to the
/// hand's geometry, fingers excepted.
pub fn palm_reach(desc: &RobotDesc) -> f64 {
    let arm = ArmModel::new(desc);
    let last = arm.dof - 1;
    let mut mats = Materials::default();
    let mut colliders = links::link_colliders(desc, &arm, last, 0, &mut mats);
    colliders.push(links::palm(desc, &arm, 0));
    // The tool frame in the last link's frame (as `Robot::measured_tcp` composes it).
    let tcp = Translation3::new(desc.gripper.tcp_offset, 0.0, 0.0);
    let tool = arm.flange.map_or(Isometry3::from(tcp), |f| f * tcp);
    let ahead = vec_to_glam(&Vector3::x());
    colliders
        .iter()
        .map(|co| {
            let co = co.build();
            // The collider in the tool frame; its point furthest along the approach axis.
            let local = tool.inverse() * pose_to_iso(co.position());
            let pose = iso_to_pose(&local);
            let dir = pose.rotation.inverse() * ahead;
            let tip = match co.shape().as_support_map() {
                Some(s) => f64::from((pose * s.local_support_point(dir)).x),
                None => f64::from(co.shape().compute_aabb(&pose).maxs.x),
            };
            -tip
        })
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shipped hand: its palm box's face 4.5 cm behind the TCP, and the wrist capsule's
    /// rounded end (2.5 cm radius, its axis ending 6.5 cm behind) 4 cm behind.
    #[test]
    fn the_shipped_hand_stands_its_wrist_capsules_end_behind_the_tool_centre() {
        let reach = palm_reach(&RobotDesc::load_default().unwrap());
        assert!((reach - 0.040).abs() < 1e-6, "{reach}");
    }
}
