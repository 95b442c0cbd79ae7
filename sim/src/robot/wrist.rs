//! How high a robot's wrist stands above its tool centre point when the tool points straight
//! down: the headroom a top-down hand needs under a shelf board (the oracle caps its tool
//! heights by it, `episode/src/oracle/headroom.rs`). Read off the arm's own kinematics rather
//! than a constant, because mounted arms differ widely: a UR5e's wrist joints stand 0.24 m above
//! the fingertips of its Robotiq gripper, a Kinova Gen3's 0.33 m, the shipped arm's 0.17 m.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::FRAC_PI_2;

use super::desc::RobotDesc;
use super::ik::{IkOptions, solve};
use super::kinematics::ArmModel;

/// The reference work pose, base frame: a hand over a counter ahead of the arm's side of the
/// base (the oracle's typical pick and place height), tool straight down.
const WORK: [f64; 3] = [0.60, -0.12, 0.95];
/// Joints this close to the TCP's vertical (m) count as the wrist; the elbow and forearm stand
/// further back, outside the column a shelf board overhangs.
const WRIST_RADIUS: f64 = 0.16;

/// The highest wrist joint above the TCP (m) with the tool pointing down at a reference work
/// pose, solved from the home pose by [`solve`]; `None` when the arm cannot reach the pose.
pub fn wrist_height(desc: &RobotDesc) -> Option<f64> {
    let arm = ArmModel::new(desc);
    let home = arm.vec(&desc.arm.home);
    let down = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), FRAC_PI_2);
    let target = Isometry3::from_parts(Translation3::new(WORK[0], WORK[1], WORK[2]), down);
    let options = IkOptions {
        max_iterations: 2000,
        ..IkOptions::default()
    };
    let q = solve(&arm, &target, &home, &home, &options).ok()?;
    let fk = arm.forward(&q);
    (0..arm.dof)
        .map(|i| fk.joints[i].translation.vector - target.translation.vector)
        .filter(|d| d.xy().norm() < WRIST_RADIUS)
        .map(|d| d.z)
        .max_by(f64::total_cmp)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_wrist_stands_its_rotate_link_and_tcp_offset_above_the_tool() {
        // wrist_angle → wrist_rotate 0.07 m, wrist_rotate → TCP 0.10 m (the shipped URDF).
        let h = wrist_height(&RobotDesc::load_default().unwrap()).unwrap();
        assert!((h - 0.17).abs() < 1e-4, "{h}");
    }
}
