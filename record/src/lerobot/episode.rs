//! One episode on its way into the dataset: rows and video frames accumulated as the episode
//! runs (video encoded on the fly, so raw frames are never buffered), then staged to disk when
//! the episode is kept. [`super::LeRobotDataset`] joins staged episodes into the dataset's files.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::stats::FeatureStats;
use super::{CameraSpec, LeRobotError, io_err, write_atomic};
use crate::video::{Codec, VideoEncoder, VideoSettings};
use crate::{EpisodeMeta, Frame};

/// The 10 values of the action and of `observation.state`, named alike: the state is the
/// measured counterpart of the commanded action (base twist, hand pose in the base frame,
/// gripper opening) — the paper's robot state.
pub(crate) const ACTION_NAMES: [&str; 10] = ["v", "omega", "x", "y", "z", "qw", "qx", "qy", "qz", "gripper"];

/// A numeric per-frame feature: `values` holds `names.len()` floats per frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Column {
    pub key: String,
    pub names: Vec<String>,
    pub values: Vec<f32>,
}

/// What a kept episode leaves in the staging folder (`<index>.json`, written last, marks the
/// staged episode complete; one `<index>.<camera>.krav1` per camera).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct StagedEpisode {
    pub collect_index: usize,
    pub episode_id: String,
    pub scene: String,
    pub instruction: String,
    /// The episode's sub-task sentences in order of first appearance.
    pub tasks: Vec<String>,
    /// For each frame, its sentence as an index into `tasks`.
    pub frame_task: Vec<u32>,
    pub columns: Vec<Column>,
    pub cameras: Vec<CameraSpec>,
    /// Per-camera image statistics, in `cameras` order.
    pub image_stats: Vec<FeatureStats>,
    /// The codec of the staged clips (episodes staged before H.264 existed are AV1).
    #[serde(default = "codec_before_h264")]
    pub codec: Codec,
}

/// What a staged episode or dataset without a `codec` field was encoded with.
pub(crate) fn codec_before_h264() -> Codec {
    Codec::Av1
}

impl StagedEpisode {
    pub(crate) fn len(&self) -> usize {
        self.frame_task.len()
    }

    pub(crate) fn json_path(staging: &Path, index: usize) -> PathBuf {
        staging.join(format!("ep{index:05}.json"))
    }

    pub(crate) fn video_path(staging: &Path, index: usize, camera: &str) -> PathBuf {
        staging.join(format!("ep{index:05}.{camera}.krav1"))
    }

    pub(crate) fn load(staging: &Path, index: usize) -> Result<StagedEpisode, LeRobotError> {
        let path = Self::json_path(staging, index);
        let text = std::fs::read_to_string(&path).map_err(io_err(&path))?;
        serde_json::from_str(&text).map_err(|e| LeRobotError::Json {
            path,
            message: e.to_string(),
        })
    }
}

struct Track {
    spec: CameraSpec,
    encoder: VideoEncoder,
    hist: [[u64; 256]; 3],
}

/// Records one episode for the LeRobotDataset.
pub struct EpisodeRecorder {
    collect_index: usize,
    meta: EpisodeMeta,
    columns: Vec<Column>,
    plan_step: Vec<usize>,
    tracks: Vec<Track>,
    codec: Codec,
}

impl std::fmt::Debug for EpisodeRecorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EpisodeRecorder")
            .field("collect_index", &self.collect_index)
            .field("frames", &self.plan_step.len())
            .finish()
    }
}

impl EpisodeRecorder {
    /// An episode (`collect_index` names its files) whose frames carry exactly `cameras`.
    pub fn new(
        collect_index: usize,
        meta: EpisodeMeta,
        cameras: &[CameraSpec],
        video: VideoSettings,
    ) -> Result<EpisodeRecorder, LeRobotError> {
        let tracks = cameras
            .iter()
            .map(|c| {
                Ok(Track {
                    spec: c.clone(),
                    encoder: VideoEncoder::new(c.width, c.height, super::FPS, video)?,
                    hist: [[0; 256]; 3],
                })
            })
            .collect::<Result<_, LeRobotError>>()?;
        Ok(EpisodeRecorder {
            collect_index,
            meta,
            columns: Vec::new(),
            plan_step: Vec::new(),
            tracks,
            codec: video.codec,
        })
    }

    pub fn push(&mut self, f: &Frame) -> Result<(), LeRobotError> {
        let index = self.plan_step.len();
        let names: Vec<&str> = f.cameras.iter().map(|c| c.name.as_str()).collect();
        let wanted: Vec<&str> = self.tracks.iter().map(|t| t.spec.name.as_str()).collect();
        if names != wanted {
            return Err(LeRobotError::Frame(format!(
                "frame {index} has cameras {names:?}, the dataset {wanted:?}"
            )));
        }
        for (t, c) in self.tracks.iter_mut().zip(&f.cameras) {
            t.encoder.push_rgb(&c.rgb)?;
            for px in c.rgb.chunks_exact(3) {
                for (h, v) in t.hist.iter_mut().zip(px) {
                    h[usize::from(*v)] += 1;
                }
            }
        }
        let gripper = f.qpos.last().copied().unwrap_or(0.0);
        let state: Vec<f64> = f
            .base_twist
            .iter()
            .chain(&f.ee_pose)
            .copied()
            .chain([gripper])
            .collect();
        let joints = f.qpos.len().saturating_sub(1);
        let joint_names = (0..joints)
            .map(|j| format!("joint_{j}"))
            .chain(["gripper".to_string()]);
        let rows: [(&str, Vec<String>, &[f64]); 4] = [
            ("observation.state", names_of(&ACTION_NAMES), &state),
            ("observation.joints", joint_names.collect(), &f.qpos),
            (
                "observation.base_pose",
                names_of(&["x", "y", "yaw"]),
                &f.base_pose,
            ),
            ("action", names_of(&ACTION_NAMES), &f.action),
        ];
        if self.columns.is_empty() {
            self.columns = rows
                .iter()
                .map(|(key, names, _)| Column {
                    key: key.to_string(),
                    names: names.clone(),
                    values: Vec::new(),
                })
                .collect();
        }
        for (col, (_, names, v)) in self.columns.iter_mut().zip(&rows) {
            if v.len() != col.names.len() || names.len() != col.names.len() {
                return Err(LeRobotError::Frame(format!(
                    "frame {index}: {} has {} values, earlier frames {}",
                    col.key,
                    v.len(),
                    col.names.len()
                )));
            }
            col.values.extend(v.iter().map(|x| *x as f32));
        }
        self.plan_step.push(f.task);
        Ok(())
    }

    /// Stage the episode under `staging` (videos first, the JSON that marks it complete last).
    pub fn finish(self, staging: &Path) -> Result<(), LeRobotError> {
        std::fs::create_dir_all(staging).map_err(io_err(staging))?;
        let i = self.collect_index;
        let mut tasks: Vec<String> = Vec::new();
        let mut frame_task = Vec::with_capacity(self.plan_step.len());
        for step in &self.plan_step {
            let sentence = self.meta.plan.get(*step).cloned().unwrap_or_default();
            let at = match tasks.iter().position(|t| *t == sentence) {
                Some(at) => at,
                None => {
                    tasks.push(sentence);
                    tasks.len() - 1
                }
            };
            frame_task.push(at as u32);
        }
        let frames = self.plan_step.len() as u64;
        let mut cameras = Vec::new();
        let mut image_stats = Vec::new();
        for t in self.tracks {
            let clip = t.encoder.finish()?;
            let path = StagedEpisode::video_path(staging, i, &t.spec.name);
            write_atomic(&path, |p| Ok(clip.save(p)?))?;
            image_stats.push(FeatureStats::of_histograms(&t.hist, frames));
            cameras.push(t.spec);
        }
        let staged = StagedEpisode {
            collect_index: i,
            episode_id: self.meta.episode_id,
            scene: self.meta.scene,
            instruction: self.meta.instruction,
            tasks,
            frame_task,
            columns: self.columns,
            cameras,
            image_stats,
            codec: self.codec,
        };
        let path = StagedEpisode::json_path(staging, i);
        let text = serde_json::to_string(&staged).map_err(|e| LeRobotError::Json {
            path: path.clone(),
            message: e.to_string(),
        })?;
        write_atomic(&path, |p| std::fs::write(p, &text).map_err(io_err(p)))
    }
}

fn names_of(n: &[&str]) -> Vec<String> {
    n.iter().map(|s| s.to_string()).collect()
}
