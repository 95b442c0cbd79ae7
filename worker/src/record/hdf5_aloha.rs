//! One HDF5 file per episode, in the layout ALOHA/ACT tooling reads.
//!
//! ```text
//! /                               attrs: sim=1, compress=0, episode_id, scene, instruction,
//!                                        plan (JSON list), tasks (JSON list of TaskSpan), seed
//! /observations/images/<cam>      uint8   (T, H, W, 3)   RGB
//! /observations/depth/<cam>       float32 (T, H, W)      metres
//! /observations/qpos              float64 (T, J+1)       arm joints then gripper opening
//! /observations/qvel              float64 (T, J+1)
//! /observations/base_pose         float64 (T, 3)         odometry x, y, yaw
//! /observations/ee_pose           float64 (T, 7)         x y z qw qx qy qz in the base frame
//! /action                         float64 (T, 10)        v ω x y z qw qx qy qz g
//! /base_action                    float64 (T, 2)         v ω (Mobile ALOHA's name)
//! /task_index                     int32   (T,)           plan step being executed
//! /task_start, /task_end          int64   (K,)           frame span of each plan step
//! /task_success                   uint8   (K,)
//! ```
//! Every frame must carry every camera: ACT indexes images and actions by the same t.

use std::path::Path;

use hdf5::types::VarLenUnicode;
use ndarray::{Array1, Array2, Array3, Array4};

use super::{EpisodeMeta, Frame, RecordError, TaskSpan};

/// Buffers an episode's frames and writes the file at the end (an episode is tens of MB).
pub struct Hdf5Recorder {
    meta: EpisodeMeta,
    frames: Vec<Frame>,
}

impl Hdf5Recorder {
    pub fn new(meta: EpisodeMeta) -> Self {
        Hdf5Recorder {
            meta,
            frames: Vec::new(),
        }
    }

    pub fn push(&mut self, frame: Frame) -> Result<(), RecordError> {
        if let Some(first) = self.frames.first() {
            let same = first.cameras.len() == frame.cameras.len()
                && first
                    .cameras
                    .iter()
                    .zip(&frame.cameras)
                    .all(|(a, b)| a.name == b.name && a.width == b.width && a.height == b.height)
                && first.qpos.len() == frame.qpos.len();
            if !same {
                return Err(RecordError::Frame {
                    index: self.frames.len(),
                    message: "cameras or joint count differ from the first frame".into(),
                });
            }
        }
        for c in &frame.cameras {
            let n = (c.width * c.height) as usize;
            if c.rgb.len() != 3 * n || c.depth.len() != n {
                return Err(RecordError::Frame {
                    index: self.frames.len(),
                    message: format!("camera {} buffers do not match {}x{}", c.name, c.width, c.height),
                });
            }
        }
        self.frames.push(frame);
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Write the file at `path` (replacing it).
    pub fn finish(self, path: &Path, tasks: &[TaskSpan]) -> Result<(), RecordError> {
        let file = hdf5::File::create(path)?;
        let str_attr = |name: &str, value: &str| -> Result<(), RecordError> {
            let v: VarLenUnicode = value.parse().unwrap_or_default();
            file.new_attr::<VarLenUnicode>().create(name)?.write_scalar(&v)?;
            Ok(())
        };
        str_attr("episode_id", &self.meta.episode_id)?;
        str_attr("scene", &self.meta.scene)?;
        str_attr("instruction", &self.meta.instruction)?;
        str_attr(
            "plan",
            &serde_json::to_string(&self.meta.plan).unwrap_or_default(),
        )?;
        str_attr("tasks", &serde_json::to_string(tasks).unwrap_or_default())?;
        file.new_attr::<u8>().create("sim")?.write_scalar(&1u8)?;
        file.new_attr::<u8>().create("compress")?.write_scalar(&0u8)?;
        file.new_attr::<u64>()
            .create("seed")?
            .write_scalar(&self.meta.seed)?;

        let t = self.frames.len();
        let obs = file.create_group("observations")?;
        let images = obs.create_group("images")?;
        let depth = obs.create_group("depth")?;
        if let Some(first) = self.frames.first() {
            for (ci, cam) in first.cameras.iter().enumerate() {
                let (h, w) = (cam.height as usize, cam.width as usize);
                let mut rgb = Array4::<u8>::zeros((t, h, w, 3));
                let mut d = Array3::<f32>::zeros((t, h, w));
                for (fi, f) in self.frames.iter().enumerate() {
                    let c = &f.cameras[ci];
                    rgb.index_axis_mut(ndarray::Axis(0), fi)
                        .as_slice_mut()
                        .expect("standard layout")
                        .copy_from_slice(&c.rgb);
                    d.index_axis_mut(ndarray::Axis(0), fi)
                        .as_slice_mut()
                        .expect("standard layout")
                        .copy_from_slice(&c.depth);
                }
                images
                    .new_dataset_builder()
                    .with_data(&rgb)
                    .chunk((1, h, w, 3))
                    .create(cam.name.as_str())?;
                depth
                    .new_dataset_builder()
                    .with_data(&d)
                    .chunk((1, h, w))
                    .create(cam.name.as_str())?;
            }
        }
        let rows = |get: &dyn Fn(&Frame) -> Vec<f64>| -> Array2<f64> {
            let cols = self.frames.first().map(|f| get(f).len()).unwrap_or(0);
            let flat: Vec<f64> = self.frames.iter().flat_map(get).collect();
            Array2::from_shape_vec((t, cols), flat).expect("rows of equal length")
        };
        let write2 = |g: &hdf5::Group, name: &str, a: Array2<f64>| -> Result<(), RecordError> {
            g.new_dataset_builder().with_data(&a).create(name)?;
            Ok(())
        };
        write2(&obs, "qpos", rows(&|f| f.qpos.clone()))?;
        write2(&obs, "qvel", rows(&|f| f.qvel.clone()))?;
        write2(&obs, "base_pose", rows(&|f| f.base_pose.to_vec()))?;
        write2(&obs, "ee_pose", rows(&|f| f.ee_pose.to_vec()))?;
        write2(&file, "action", rows(&|f| f.action.to_vec()))?;
        write2(&file, "base_action", rows(&|f| f.action[..2].to_vec()))?;
        let task_index: Array1<i32> = self.frames.iter().map(|f| f.task as i32).collect();
        file.new_dataset_builder()
            .with_data(&task_index)
            .create("task_index")?;
        let starts: Array1<i64> = tasks.iter().map(|s| s.start as i64).collect();
        let ends: Array1<i64> = tasks.iter().map(|s| s.end as i64).collect();
        let ok: Array1<u8> = tasks.iter().map(|s| s.success as u8).collect();
        file.new_dataset_builder()
            .with_data(&starts)
            .create("task_start")?;
        file.new_dataset_builder().with_data(&ends).create("task_end")?;
        file.new_dataset_builder().with_data(&ok).create("task_success")?;
        file.close()?;
        Ok(())
    }
}
