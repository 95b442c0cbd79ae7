//! The kitchen twin: scene loading, rapier3d physics, the mobile manipulator (differential-drive
//! base, 6-DoF arm under an RMPflow-style controller, parallel gripper), cameras and LiDAR by ray
//! casting, success checks and monitors, and seeded episode configurations. No networking.
//!
//! Conventions: world frame z up, metres, x east, y north, yaw counter-clockwise. Robot base frame
//! at the base's centre on the floor, x forward, y left, z up. An [`Action`] is
//! `(v, ω, x, y, z, qw, qx, qy, qz, g)`: base velocities, the TCP target pose in the base frame and
//! the gripper command (0 closed, 1 open), applied for one 0.1 s control step of fixed physics
//! substeps. See `kitchen_r_core::robot` and docs/twin/robot.md for the arm and TCP frames.

pub mod bench;
pub mod bodies;
pub mod config;
pub mod convert;
pub mod episode;
pub mod error;
pub mod furniture;
pub mod generator;
pub mod grasp;
pub mod material;
pub mod mesh;
mod mesh_mjcf;
mod mesh_raw;
pub mod oracle;
pub mod preflight;
pub mod randomise;
pub mod randomise_settings;
pub mod render;
pub mod report;
pub mod robot;
pub mod seeds;
pub mod sensors;
pub mod sim;
pub mod snapshot;
pub mod task;
#[cfg(test)]
mod test_support;
pub mod types;
pub mod usd_export;
pub mod world;

pub use config::{RobotConfig, SensorsConfig, SimConfig, override_robot};
pub use episode::{EpisodeConfig, ObjectPlacement};
pub use error::SimError;
pub use generator::EpisodeParams;
pub use randomise::{Randomise, randomise};
pub use sim::{Assets, Sim};
pub use snapshot::Snapshot;
pub use task::{TaskTarget, task_target};
pub use types::{Action, Observation, StepInfo};
