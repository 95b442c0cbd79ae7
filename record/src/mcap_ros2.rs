//! MCAP writer with ROS 2 encodings (`ros2msg` schemas, `cdr` messages, profile `ros2`).
//!
//! Topics (frame ids in brackets):
//! - `/camera/<cam>/image_raw` `sensor_msgs/Image` rgb8 [`<cam>_optical_frame`]
//! - `/camera/<cam>/depth` `sensor_msgs/Image` 32FC1, metres [`<cam>_optical_frame`]
//! - `/lidar/points` `sensor_msgs/PointCloud2` xyz float32 [`lidar`]
//! - `/camera/<cam>/depth` is absent when depth is not recorded (`collect --no-depth`)
//! - `/odom` `nav_msgs/Odometry` [`odom` → `base_link`]
//! - `/imu` `sensor_msgs/Imu` [`base_link`]: the base's motion (yaw, yaw rate, acceleration
//!   from the change of base speed plus gravity on z; covariances in `ros2_msgs::IMU_COVARIANCE`)
//! - `/tf` `tf2_msgs/TFMessage` (odom → base_link, base_link → ee_link) and `/tf_static` (sensor mounts)
//! - `/cmd_vel` `geometry_msgs/Twist`: the commanded base twist
//! - `/action` `std_msgs/Float64MultiArray`: the 10-value action
//!
//! Episode metadata (instruction, plan, task spans) is written as MCAP metadata records.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use mcap::records::MessageHeader;

use crate::rate::RateMonitor;
use crate::ros2_msgs as msg;
use crate::{EpisodeMeta, Frame, RecordError, TaskSpan, nanos};

pub struct McapRecorder {
    writer: mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    channels: BTreeMap<String, u16>,
    sequence: u32,
    /// The previous frame's time and base twist, for the IMU's acceleration.
    previous: Option<(f64, [f64; 2])>,
    /// Messages written per topic, for summaries and tests.
    pub counts: BTreeMap<String, u64>,
}

impl McapRecorder {
    /// Create the file and write the static transforms and episode metadata.
    pub fn create(path: &Path, meta: &EpisodeMeta) -> Result<Self, RecordError> {
        let file = File::create(path).map_err(|source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .compression(Some(mcap::Compression::Zstd))
            .create(BufWriter::new(file))?;
        let mut rec = McapRecorder {
            writer,
            path: path.to_path_buf(),
            channels: BTreeMap::new(),
            sequence: 0,
            previous: None,
            counts: BTreeMap::new(),
        };
        let mut md = BTreeMap::new();
        md.insert("episode_id".to_string(), meta.episode_id.clone());
        md.insert("scene".to_string(), meta.scene.clone());
        md.insert("instruction".to_string(), meta.instruction.clone());
        md.insert(
            "plan".to_string(),
            serde_json::to_string(&meta.plan).unwrap_or_default(),
        );
        md.insert("seed".to_string(), meta.seed.to_string());
        rec.writer.write_metadata(&mcap::records::Metadata {
            name: "episode".into(),
            metadata: md,
        })?;
        let mounts: Vec<msg::Tf<'_>> = meta
            .sensor_mounts
            .iter()
            .map(|m| (m.parent.as_str(), m.child.as_str(), m.translation, m.rotation))
            .collect();
        let data = msg::tf_message(0.0, &mounts);
        rec.publish("/tf_static", "tf2_msgs/TFMessage", 0.0, &data, None)?;
        Ok(rec)
    }

    fn channel(&mut self, topic: &str, ty: &str) -> Result<u16, RecordError> {
        if let Some(id) = self.channels.get(topic) {
            return Ok(*id);
        }
        let schema = self
            .writer
            .add_schema(&msg::schema_name(ty), "ros2msg", msg::schema(ty).as_bytes())?;
        let id = self.writer.add_channel(schema, topic, "cdr", &BTreeMap::new())?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    fn publish(
        &mut self,
        topic: &str,
        ty: &str,
        t: f64,
        data: &[u8],
        rate: Option<&mut RateMonitor>,
    ) -> Result<(), RecordError> {
        let channel_id = self.channel(topic, ty)?;
        self.sequence += 1;
        let header = MessageHeader {
            channel_id,
            sequence: self.sequence,
            log_time: nanos(t),
            publish_time: nanos(t),
        };
        self.writer.write_to_known_channel(&header, data)?;
        *self.counts.entry(topic.to_string()).or_default() += 1;
        if let Some(r) = rate {
            r.record(topic, t);
        }
        Ok(())
    }

    /// Write every message of one frame; each publication is reported to `rate`.
    pub fn write_frame(&mut self, f: &Frame, mut rate: Option<&mut RateMonitor>) -> Result<(), RecordError> {
        let t = f.time;
        for cam in &f.cameras {
            let frame_id = format!("{}_optical_frame", cam.name);
            let rgb = msg::image(
                t,
                &frame_id,
                cam.width,
                cam.height,
                "rgb8",
                cam.width * 3,
                &cam.rgb,
            );
            self.publish(
                &format!("/camera/{}/image_raw", cam.name),
                "sensor_msgs/Image",
                t,
                &rgb,
                rate.as_deref_mut(),
            )?;
            if cam.depth.is_empty() {
                continue;
            }
            let depth_bytes: Vec<u8> = cam.depth.iter().flat_map(|d| d.to_le_bytes()).collect();
            let depth = msg::image(
                t,
                &frame_id,
                cam.width,
                cam.height,
                "32FC1",
                cam.width * 4,
                &depth_bytes,
            );
            self.publish(
                &format!("/camera/{}/depth", cam.name),
                "sensor_msgs/Image",
                t,
                &depth,
                rate.as_deref_mut(),
            )?;
        }
        if let Some(points) = &f.lidar {
            let pc = msg::point_cloud(t, "lidar", points);
            self.publish(
                "/lidar/points",
                "sensor_msgs/PointCloud2",
                t,
                &pc,
                rate.as_deref_mut(),
            )?;
        }
        let odom = msg::odometry(t, f.base_pose, f.base_twist);
        self.publish("/odom", "nav_msgs/Odometry", t, &odom, rate.as_deref_mut())?;
        let imu = msg::imu(t, f.base_pose[2], f.base_twist, self.previous);
        self.previous = Some((t, f.base_twist));
        self.publish("/imu", "sensor_msgs/Imu", t, &imu, rate.as_deref_mut())?;
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
        self.publish("/tf", "tf2_msgs/TFMessage", t, &tf, rate.as_deref_mut())?;
        let cmd = msg::twist(f.action[0], f.action[1]);
        self.publish("/cmd_vel", "geometry_msgs/Twist", t, &cmd, rate.as_deref_mut())?;
        let action = msg::float64_array("v,w,x,y,z,qw,qx,qy,qz,g", &f.action);
        self.publish("/action", "std_msgs/Float64MultiArray", t, &action, rate)?;
        Ok(())
    }

    /// Write the task spans and close the file.
    pub fn finish(mut self, tasks: &[TaskSpan]) -> Result<PathBuf, RecordError> {
        let mut md = BTreeMap::new();
        md.insert(
            "tasks".to_string(),
            serde_json::to_string(tasks).unwrap_or_default(),
        );
        self.writer.write_metadata(&mcap::records::Metadata {
            name: "tasks".into(),
            metadata: md,
        })?;
        self.writer.finish()?;
        Ok(self.path)
    }
}
