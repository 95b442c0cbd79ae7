//! One HDF5 file per episode, in the layout ALOHA/ACT tooling reads.
//!
//! ```text
//! /                               attrs: sim=1, compress=0, episode_id, scene, instruction,
//!                                        plan (JSON list), tasks (JSON list of TaskSpan), seed
//! /observations/images/<cam>      uint8   (T, H, W, 3)   RGB
//! /observations/depth/<cam>       float32 (T, H, W)      metres, or uint16 millimetres
//!                                                        (attr `unit` = "m" or "mm"); absent
//!                                                        when depth is not recorded
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
//!
//! Images and depth are chunked one frame per chunk (ACT samples single timesteps, so a read
//! decompresses only the frame it needs) and compressed with shuffle + deflate, the filters
//! libhdf5 and so h5py always have: no plugin is needed to read the file. Raw, an average dev
//! episode was ~240 MB; compressed with millimetre depth it is a tenth of that (docs/measured/performance.md).

use std::path::Path;

use rust_hdf5::types::VarLenUnicode;
use rust_hdf5::{H5Dataset, H5File, H5Group, H5Type};

use crate::{EpisodeMeta, Frame, RecordError, TaskSpan};

/// How `/observations/depth/<cam>` stores depth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DepthUnit {
    /// float32 metres, as the simulator renders it.
    Metres,
    /// uint16 millimetres (0 = no return; clamped at 65.535 m): half the bytes, and integer
    /// data compresses several times better than float noise.
    #[default]
    Millimetres,
}

/// Storage options of the HDF5 file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hdf5Options {
    pub depth: DepthUnit,
    /// Deflate level 0–9 of the image and depth datasets (0 = chunked but uncompressed).
    pub deflate: u32,
}

impl Default for Hdf5Options {
    fn default() -> Self {
        // Level 4: within a few percent of level 9's size on rendered frames, several times faster.
        Hdf5Options {
            depth: DepthUnit::default(),
            deflate: 4,
        }
    }
}

/// Buffers an episode's frames and writes the file at the end (an episode is tens of MB).
pub struct Hdf5Recorder {
    meta: EpisodeMeta,
    options: Hdf5Options,
    frames: Vec<Frame>,
}

impl Hdf5Recorder {
    pub fn new(meta: EpisodeMeta, options: Hdf5Options) -> Self {
        Hdf5Recorder {
            meta,
            options,
            frames: Vec::new(),
        }
    }

    pub fn push(&mut self, frame: Frame) -> Result<(), RecordError> {
        if let Some(first) = self.frames.first() {
            let same = first.cameras.len() == frame.cameras.len()
                && first.cameras.iter().zip(&frame.cameras).all(|(a, b)| {
                    a.name == b.name
                        && a.width == b.width
                        && a.height == b.height
                        && a.depth.is_empty() == b.depth.is_empty()
                })
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
            // An empty depth buffer means depth is not recorded (`collect --no-depth`).
            let depth_ok = c.depth.len() == n || c.depth.is_empty();
            if c.rgb.len() != 3 * n || !depth_ok {
                return Err(RecordError::Frame {
                    index: self.frames.len(),
                    message: format!("camera {} buffers do not match {}x{}", c.name, c.width, c.height),
                });
            }
        }
        self.frames.push(frame);
        Ok(())
    }

    /// Write the file at `path` (replacing it).
    pub fn finish(self, path: &Path, tasks: &[TaskSpan]) -> Result<(), RecordError> {
        let file = H5File::create(path)?;
        let root = file.root_group();
        root.set_attr_string("episode_id", &self.meta.episode_id)?;
        root.set_attr_string("scene", &self.meta.scene)?;
        root.set_attr_string("instruction", &self.meta.instruction)?;
        root.set_attr_string("plan", &json(&self.meta.plan))?;
        root.set_attr_string("tasks", &json(tasks))?;
        root.set_attr_numeric("sim", &1u8)?;
        root.set_attr_numeric("compress", &0u8)?;
        root.set_attr_numeric("seed", &self.meta.seed)?;

        let t = self.frames.len();
        let obs = root.create_group("observations")?;
        let images = obs.create_group("images")?;
        let with_depth = self
            .frames
            .first()
            .is_some_and(|f| f.cameras.iter().all(|c| !c.depth.is_empty()));
        let depth = if with_depth {
            Some(obs.create_group("depth")?)
        } else {
            None
        };
        let level = self.options.deflate;
        if let Some(first) = self.frames.first() {
            for (ci, cam) in first.cameras.iter().enumerate() {
                let (h, w) = (cam.height as usize, cam.width as usize);
                let rgb: Vec<u8> = self
                    .frames
                    .iter()
                    .flat_map(|f| f.cameras[ci].rgb.iter().copied())
                    .collect();
                write_frames(&images, &cam.name, &[t, h, w, 3], &rgb, level)?;
                let Some(depth) = &depth else { continue };
                let metres = self
                    .frames
                    .iter()
                    .flat_map(|f| f.cameras[ci].depth.iter().copied());
                let ds = match self.options.depth {
                    DepthUnit::Metres => {
                        let d: Vec<f32> = metres.collect();
                        write_frames(depth, &cam.name, &[t, h, w], &d, level)?
                    }
                    DepthUnit::Millimetres => {
                        let d: Vec<u16> = metres.map(millimetres).collect();
                        write_frames(depth, &cam.name, &[t, h, w], &d, level)?
                    }
                };
                let unit = match self.options.depth {
                    DepthUnit::Metres => "m",
                    DepthUnit::Millimetres => "mm",
                };
                ds.new_attr::<VarLenUnicode>()
                    .shape(())
                    .create("unit")?
                    .write_scalar(&VarLenUnicode(unit.into()))?;
            }
        }
        let rows = |get: &dyn Fn(&Frame) -> Vec<f64>| -> (Vec<f64>, usize) {
            let cols = self.frames.first().map(|f| get(f).len()).unwrap_or(0);
            (self.frames.iter().flat_map(get).collect(), cols)
        };
        let table =
            |g: &H5Group, name: &str, (data, cols): (Vec<f64>, usize)| write(g, name, &[t, cols], &data);
        table(&obs, "qpos", rows(&|f| f.qpos.clone()))?;
        table(&obs, "qvel", rows(&|f| f.qvel.clone()))?;
        table(&obs, "base_pose", rows(&|f| f.base_pose.to_vec()))?;
        table(&obs, "ee_pose", rows(&|f| f.ee_pose.to_vec()))?;
        table(&root, "action", rows(&|f| f.action.to_vec()))?;
        table(&root, "base_action", rows(&|f| f.action[..2].to_vec()))?;
        let task_index: Vec<i32> = self.frames.iter().map(|f| f.task as i32).collect();
        write(&root, "task_index", &[t], &task_index)?;
        let k = tasks.len();
        let starts: Vec<i64> = tasks.iter().map(|s| s.start as i64).collect();
        let ends: Vec<i64> = tasks.iter().map(|s| s.end as i64).collect();
        let ok: Vec<u8> = tasks.iter().map(|s| s.success as u8).collect();
        write(&root, "task_start", &[k], &starts)?;
        write(&root, "task_end", &[k], &ends)?;
        write(&root, "task_success", &[k], &ok)?;
        file.close()?;
        Ok(())
    }
}

fn json<T: serde::Serialize + ?Sized>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_default()
}

/// Depth in metres to uint16 millimetres (0 stays 0: no return).
fn millimetres(m: f32) -> u16 {
    (m * 1000.0).round().clamp(0.0, f32::from(u16::MAX)) as u16
}

/// A `(T, ...)` dataset chunked one frame per chunk, shuffled and deflated.
fn write_frames<T: H5Type>(
    g: &H5Group,
    name: &str,
    shape: &[usize],
    data: &[T],
    level: u32,
) -> Result<H5Dataset, RecordError> {
    let mut chunk = shape.to_vec();
    chunk[0] = 1;
    let builder = g.new_dataset::<T>().shape(shape).chunk(&chunk);
    let builder = if level > 0 {
        builder.shuffle_deflate(level)
    } else {
        builder
    };
    let ds = builder.create(name)?;
    ds.write_raw(data)?;
    Ok(ds)
}

/// A dataset of `shape` holding `data` in row-major order.
fn write<T: H5Type>(g: &H5Group, name: &str, shape: &[usize], data: &[T]) -> Result<(), RecordError> {
    g.new_dataset::<T>().shape(shape).create(name)?.write_raw(data)?;
    Ok(())
}
