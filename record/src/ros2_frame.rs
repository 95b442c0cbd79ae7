//! The ROS 2 messages of one recorded control step, in the order they are written: the one
//! place that decides topics, types and frame ids, for the MCAP recorder
//! ([`crate::mcap_ros2`], whose module doc lists them) and the live publishers
//! ([`crate::live`]) alike.

use kitchen_r_sim::SensorsConfig;

use crate::ros2_msgs::{self as msg, Ros2Message};
use crate::{CameraFrame, EpisodeMeta, Frame};

/// The base's time and twist at the previous frame: the IMU's acceleration is the change of
/// the base speed since then.
pub type ImuMemory = Option<(f64, [f64; 2])>;

fn message(topic: impl Into<String>, ty: &'static str, stamp: f64, data: Vec<u8>) -> Ros2Message {
    Ros2Message {
        topic: topic.into(),
        ty,
        stamp,
        data,
    }
}

/// `/tf_static`: the sensor mounts, stamped at the episode's start.
pub fn static_transforms(meta: &EpisodeMeta) -> Ros2Message {
    let mounts: Vec<msg::Tf<'_>> = meta
        .sensor_mounts
        .iter()
        .map(|m| (m.parent.as_str(), m.child.as_str(), m.translation, m.rotation))
        .collect();
    message(
        "/tf_static",
        "tf2_msgs/TFMessage",
        0.0,
        msg::tf_message(0.0, &mounts),
    )
}

/// `/sub_task` (`std_msgs/String`): the plan step a task runs, published when it starts.
pub fn sub_task(stamp: f64, step: &str) -> Ros2Message {
    message("/sub_task", "std_msgs/String", stamp, msg::string(step))
}

/// Every message of frame `f`; `imu` is the previous frame's base motion and is updated.
pub fn frame_messages(f: &Frame, imu: &mut ImuMemory) -> Vec<Ros2Message> {
    let t = f.time;
    let mut out = Vec::with_capacity(2 * f.cameras.len() + 7);
    out.push(message("/clock", "rosgraph_msgs/Clock", t, msg::clock(t)));
    for cam in &f.cameras {
        let frame_id = format!("{}_optical_frame", cam.name);
        let (w, h) = (cam.width, cam.height);
        let rgb = msg::image(t, &frame_id, w, h, "rgb8", w * 3, &cam.rgb);
        out.push(message(
            format!("/camera/{}/image_raw", cam.name),
            "sensor_msgs/Image",
            t,
            rgb,
        ));
        if cam.depth.is_empty() {
            continue;
        }
        let bytes: Vec<u8> = cam.depth.iter().flat_map(|d| d.to_le_bytes()).collect();
        let depth = msg::image(t, &frame_id, w, h, "32FC1", w * 4, &bytes);
        out.push(message(
            format!("/camera/{}/depth", cam.name),
            "sensor_msgs/Image",
            t,
            depth,
        ));
    }
    if let Some(points) = &f.lidar {
        let pc = msg::point_cloud(t, "lidar", points);
        out.push(message("/lidar/points", "sensor_msgs/PointCloud2", t, pc));
    }
    let odom = msg::odometry(t, f.base_pose, f.base_twist);
    out.push(message("/odom", "nav_msgs/Odometry", t, odom));
    let imu_msg = msg::imu(t, f.base_pose[2], f.base_twist, *imu);
    *imu = Some((t, f.base_twist));
    out.push(message("/imu", "sensor_msgs/Imu", t, imu_msg));
    let (bt, br) = msg::base_tf(f.base_pose);
    let e = f.ee_pose;
    let tf = msg::tf_message(
        t,
        &[
            ("odom", "base_link", bt, br),
            (
                "base_link",
                "ee_link",
                [e[0], e[1], e[2]],
                [e[3], e[4], e[5], e[6]],
            ),
        ],
    );
    out.push(message("/tf", "tf2_msgs/TFMessage", t, tf));
    let cmd = msg::twist(f.action[0], f.action[1]);
    out.push(message("/cmd_vel", "geometry_msgs/Twist", t, cmd));
    let action = msg::float64_array("v,w,x,y,z,qw,qx,qy,qz,g", &f.action);
    out.push(message("/action", "std_msgs/Float64MultiArray", t, action));
    out
}

/// Every `(topic, type)` an episode with `sensors` publishes, in the order a frame writes
/// them after `/tf_static` and `/sub_task`: what a live view advertises before the first frame.
pub fn topics(sensors: &SensorsConfig) -> Vec<(String, &'static str)> {
    // A frame of the configured sensors with empty readings: its messages name every topic.
    let probe = Frame {
        time: 0.0,
        cameras: (sensors.cameras.iter())
            .map(|c| CameraFrame {
                name: c.name.clone(),
                width: c.width,
                height: c.height,
                rgb: Vec::new(),
                depth: vec![0.0],
            })
            .collect(),
        lidar: sensors.lidar.as_ref().map(|_| Vec::new()),
        base_pose: [0.0; 3],
        base_twist: [0.0; 2],
        action: [0.0; 10],
        qpos: Vec::new(),
        qvel: Vec::new(),
        ee_pose: [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0],
        task: 0,
    };
    let fixed = [static_transforms(&EpisodeMeta::default()), sub_task(0.0, "")];
    (fixed.into_iter())
        .chain(frame_messages(&probe, &mut None))
        .map(|m| (m.topic, m.ty))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_configured_sensors_name_every_topic_once() {
        let t = topics(&SensorsConfig::load_default().unwrap());
        let names: Vec<&str> = t.iter().map(|(n, _)| n.as_str()).collect();
        for want in [
            "/tf_static",
            "/sub_task",
            "/clock",
            "/camera/base/image_raw",
            "/camera/gripper/depth",
            "/odom",
            "/imu",
            "/tf",
            "/cmd_vel",
            "/action",
        ] {
            assert_eq!(
                names.iter().filter(|n| **n == want).count(),
                1,
                "{want} in {names:?}"
            );
        }
    }
}
