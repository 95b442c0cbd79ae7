//! Live ROS 2 topics over DDS (RustDDS): the messages kitchen-r-record's live publisher
//! produces, written as they are (the CDR bytes the MCAP recordings hold) to DDS topics named
//! and typed as a ROS 2 node names them (`/imu` → `rt/imu`, `sensor_msgs/Imu` →
//! `sensor_msgs::msg::dds_::Imu_`), so a stock ROS 2 node, `ros2 topic echo` or `ros2 bag
//! record` subscribes with no bridge.
//!
//! Best effort like the Foxglove view: the publisher thread writes, and a writer never waits
//! for a subscriber (a reliable writer's full send window drops the sample), so a slow or
//! stuck subscriber costs messages, never simulation time. Discovery stays on loopback unless
//! `configs/live.toml` says otherwise ([`Network`]).

mod config;
mod dds;
mod episodes;

pub use config::{DOMAIN_ENV, Durability, MAX_DOMAIN_ID, Network, Reliability, Ros2Config};
pub use dds::Ros2Publisher;
pub use episodes::Ros2Episodes;

/// Why the DDS side did not start.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    #[error("{0}")]
    Config(String),
    #[error("DDS: {0}")]
    Dds(String),
}

/// The DDS topic of ROS 2 topic `topic` (`/imu` → `rt/imu`).
pub fn dds_topic(topic: &str) -> String {
    format!("rt/{}", topic.trim_start_matches('/'))
}

/// The DDS type name of ROS 2 message type `ty` (`sensor_msgs/Imu` or `sensor_msgs/msg/Imu`
/// → `sensor_msgs::msg::dds_::Imu_`).
pub fn dds_type(ty: &str) -> String {
    let (pkg, name) = ty.split_once('/').unwrap_or(("", ty));
    let name = name.rsplit('/').next().unwrap_or(name);
    format!("{pkg}::msg::dds_::{name}_")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_those_of_a_ros_2_node() {
        assert_eq!(dds_topic("/camera/base/image_raw"), "rt/camera/base/image_raw");
        assert_eq!(dds_type("sensor_msgs/Imu"), "sensor_msgs::msg::dds_::Imu_");
        assert_eq!(
            dds_type("tf2_msgs/msg/TFMessage"),
            "tf2_msgs::msg::dds_::TFMessage_"
        );
    }
}
