//! The standard robot state vector: one frame's proprioception as 29 numbers in a fixed,
//! documented order. The Python environment's `state` (`gym_kitchen_r.STATE_FIELDS`) and an
//! openpi policy's `observation/state` are this vector, so a model trained on one reads the
//! other. Standard-track values only: odometry is relative to the episode's start.

use kitchen_r_sim::Observation;

use super::ACTION_DIM;

/// The fields of [`state_vector`], in order: odometry relative to the episode's start, base
/// velocities, arm joints, gripper opening, hand pose in the base frame, previous action
/// (zeros before the first one and after a teleport).
pub const STATE_FIELDS: [&str; 29] = [
    "odom_x",
    "odom_y",
    "odom_yaw",
    "base_v",
    "base_w",
    "joint_0",
    "joint_1",
    "joint_2",
    "joint_3",
    "joint_4",
    "joint_5",
    "gripper",
    "ee_x",
    "ee_y",
    "ee_z",
    "ee_qw",
    "ee_qx",
    "ee_qy",
    "ee_qz",
    "prev_base_v",
    "prev_base_w",
    "prev_ee_x",
    "prev_ee_y",
    "prev_ee_z",
    "prev_ee_qw",
    "prev_ee_qx",
    "prev_ee_qy",
    "prev_ee_qz",
    "prev_gripper",
];

/// Append one frame's [`STATE_FIELDS`] to `out`.
pub fn state_vector(
    o: &Observation,
    ee_pose: &[f64; 7],
    previous_action: Option<&[f64; ACTION_DIM]>,
    out: &mut Vec<f64>,
) {
    out.extend(o.odometry.pose);
    out.extend(o.odometry.velocity);
    out.extend(o.joints);
    out.push(o.gripper);
    out.extend(ee_pose);
    out.extend(previous_action.copied().unwrap_or([0.0; ACTION_DIM]));
}
