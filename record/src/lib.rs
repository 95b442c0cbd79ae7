//! Trajectory recording: the episode data model and its on-disk formats, and expert
//! trajectory collection ([`collect`]) that fills them.
//!
//! - [`mcap_ros2`]: MCAP with ROS 2 message encodings (`ros2msg` schemas, CDR payloads), the
//!   format `ros2 bag` uses, so ROS 2 tools and Foxglove open it.
//! - [`hdf5_aloha`]: one HDF5 file per episode in the layout ALOHA/ACT tooling reads.
//! - [`lerobot`]: a LeRobotDataset v3.0 (Parquet + H.264 or AV1 video), what LeRobot trains from.
//! - [`video`]: RGB frames to an H.264 (OpenH264) or AV1 (rav1e) MP4 (LeRobot's videos; episode
//!   videos).
//! - [`live`], [`live_hook`]: the same ROS 2 messages published live while an episode runs,
//!   through a bounded queue that drops rather than waits (the transports, Foxglove WebSocket,
//!   are in kitchen-r-live).
//! - [`rate`]: the Monitoring Module's recording-rate check.
//! - [`bench`](mod@bench): oracle-episode and collection throughput figures (it needs both local evaluation
//!   and collection, so it lives with collection).
//!
//! The recorder knows nothing about physics: the collector converts simulator observations into
//! [`Frame`]s. This crate writes files and fills the live queue only: it must not score submissions (the
//! episode outcome comes from kitchen-r-episode) and must not touch the network or a database.

pub mod bench;
mod cdr;
pub mod collect;
mod frame;
pub use frame::keep_cameras;
pub mod hdf5_aloha;
pub mod lerobot;
pub mod live;
pub mod live_hook;
pub mod mcap_ros2;
pub mod rate;
pub mod replay;
pub mod ros2_frame;
pub mod ros2_msgs;
#[cfg(test)]
mod test_sim;
pub mod video;

use serde::{Deserialize, Serialize};

/// One camera image of one frame: RGB8 row-major, depth in metres row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraFrame {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
    pub depth: Vec<f32>,
}

/// The robot's state and the action taken at one control step (10 Hz).
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Sim time, seconds since the episode start.
    pub time: f64,
    pub cameras: Vec<CameraFrame>,
    /// LiDAR points in the `lidar` frame, if the LiDAR was read at this step.
    pub lidar: Option<Vec<[f32; 3]>>,
    /// Odometry `[x, y, yaw]`: the base pose relative to its pose at the episode's start (the
    /// `odom` frame), the same values as the policy contract's `RobotState.base_x/y/yaw`.
    pub base_pose: [f64; 3],
    /// Measured base velocities `[v, ω]`.
    pub base_twist: [f64; 2],
    /// The 10-value action `(v, ω, x, y, z, qw, qx, qy, qz, g)` commanded at this step.
    pub action: [f64; 10],
    /// Arm joint positions then the gripper opening.
    pub qpos: Vec<f64>,
    pub qvel: Vec<f64>,
    /// End-effector pose in the base frame: `[x, y, z, qw, qx, qy, qz]`.
    pub ee_pose: [f64; 7],
    /// Index of the plan step being executed.
    pub task: usize,
}

/// A static transform from `parent` to `child` (sensor mounts), quaternion `[w, x, y, z]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StaticTransform {
    pub parent: String,
    pub child: String,
    pub translation: [f64; 3],
    pub rotation: [f64; 4],
}

/// What an episode is, written once per file.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeMeta {
    pub episode_id: String,
    pub scene: String,
    pub instruction: String,
    pub plan: Vec<String>,
    pub seed: u64,
    pub sensor_mounts: Vec<StaticTransform>,
}

/// Where each plan step starts and ends in the frame sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskSpan {
    pub step: String,
    /// First frame index of the task.
    pub start: usize,
    /// One past the last frame index.
    pub end: usize,
    pub success: bool,
    /// Sim seconds the task took.
    pub duration: f64,
}

#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("I/O error writing {path}: {source}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("MCAP error: {0}")]
    Mcap(#[from] mcap::McapError),
    #[error("HDF5 error: {0}")]
    Hdf5(#[from] rust_hdf5::Hdf5Error),
    #[error("inconsistent frame {index}: {message}")]
    Frame { index: usize, message: String },
}

/// Sim seconds to integer nanoseconds (MCAP log times).
pub(crate) fn nanos(t: f64) -> u64 {
    (t.max(0.0) * 1e9).round() as u64
}
