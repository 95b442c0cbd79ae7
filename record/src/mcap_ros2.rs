//! MCAP writer with ROS 2 encodings (`ros2msg` schemas, `cdr` messages, profile `ros2`).
//!
//! Topics (frame ids in parentheses):
//! - `/clock` `rosgraph_msgs/Clock`: the sim time of each control step
//! - `/camera/<cam>/image_raw` `sensor_msgs/Image` rgb8 (frame `<cam>_optical_frame`)
//! - `/camera/<cam>/depth` `sensor_msgs/Image` 32FC1, metres (frame `<cam>_optical_frame`)
//! - `/lidar/points` `sensor_msgs/PointCloud2` xyz float32 (frame `lidar`)
//! - `/camera/<cam>/depth` is absent when depth is not recorded (`collect --no-depth`)
//! - `/odom` `nav_msgs/Odometry` (frame `odom` → `base_link`)
//! - `/imu` `sensor_msgs/Imu` (frame `base_link`): the base's motion (yaw, yaw rate, acceleration
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
use crate::ros2_frame::{self, ImuMemory};
use crate::ros2_msgs as msg;
use crate::{EpisodeMeta, Frame, RecordError, TaskSpan, nanos};

pub struct McapRecorder {
    writer: mcap::Writer<BufWriter<File>>,
    path: PathBuf,
    channels: BTreeMap<String, u16>,
    sequence: u32,
    /// The previous frame's time and base twist, for the IMU's acceleration.
    previous: ImuMemory,
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
        let tf = ros2_frame::static_transforms(meta);
        rec.publish(&tf.topic, tf.ty, tf.stamp, &tf.data, None)?;
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
        for m in ros2_frame::frame_messages(f, &mut self.previous) {
            self.publish(&m.topic, m.ty, m.stamp, &m.data, rate.as_deref_mut())?;
        }
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
