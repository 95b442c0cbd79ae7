//! Sensors: RGB-D cameras, LiDAR and odometry, configured in `configs/sensors.toml` and rendered
//! only when an observation is requested. `png` writes images for people to look at.

pub mod camera;
mod footprint;
pub mod lidar;
pub mod png;
pub mod projection;
mod ray_shapes;
pub mod raycast;

pub use camera::CameraImage;
pub use lidar::PointCloud;
