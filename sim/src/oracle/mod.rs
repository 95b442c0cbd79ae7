//! The oracle expert's pure algorithms (paper, §Navigation Module and §Manipulation Module): the
//! parts of the reference controller that need no physics, so they can be tested on their own.
//!
//! - [`grid`]: the occupancy grid built from a scene file, obstacles inflated by the robot radius R.
//! - [`theta_star`]: Theta* any-angle paths on that grid (and an 8-connected A* reference).
//! - [`follow`]: the paper's rule-based path-following controller at 10 Hz, emitting `(v, ω)`.
//! - [`manip`]: the 10-phase pick-and-place state machine, emitting end-effector targets in the
//!   base frame and the gripper opening, raised-cosine blended between phase targets.
//!
//! - [`action`]: packs them into the 10-value action with a sign-stable quaternion.
//!
//! Together they produce the same 10-value action `(v, ω, x, y, z, qw, qx, qy, qz, g)` a
//! participant's policy produces. The oracle is **privileged**: it reads the scene geometry, the
//! true object poses and odometry straight from the twin, none of which a participant's policy
//! is given (it sees two cameras and a sub-task sentence). Participants only ever meet the oracle
//! through organiser reference runs: expert trajectories for collection and MSE, the reference
//! policy on the leaderboard, and the feasibility self-test. Nothing here may be exposed to a
//! policy under evaluation.
//!
//! Conventions (shared with the twin): world frame z up, metres, x east, y north, yaw
//! counter-clockwise from +x. Base frame: origin at the base's geometric centre at floor level,
//! x forward, y left, z up. Poses on the floor are `[x, y, yaw]`.

pub mod action;
pub mod follow;
pub mod geometry;
pub mod grid;
pub mod manip;
pub mod theta_star;

#[cfg(test)]
mod arm_tests;
#[cfg(test)]
mod follow_tests;
#[cfg(test)]
mod manip_tests;
#[cfg(test)]
mod nav_tests;
