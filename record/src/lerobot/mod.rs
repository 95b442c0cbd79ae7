//! LeRobotDataset v3.0 export (`collect --format lerobot`), the layout LeRobot ≥ 0.4 loads
//! (`lerobot/datasets/utils.py`, `dataset_metadata.py`, `dataset_writer.py`):
//!
//! ```text
//! <out>/lerobot/
//!   meta/info.json                              codebase_version "v3.0", fps 10, features, totals,
//!                                               chunks_size, data_path / video_path templates
//!   meta/stats.json                             per-feature min/max/mean/std/count/q01..q99
//!   meta/tasks.parquet                          task (the sub-task sentence, pandas index) → task_index
//!   meta/episodes/chunk-000/file-000.parquet    one row per episode: length, tasks, data and video
//!                                               locations, frame range, timestamps, stats/...
//!   data/chunk-000/file-000.parquet             observation.state, observation.joints,
//!                                               observation.base_pose, action, timestamp,
//!                                               frame_index, episode_index, index, task_index
//!   videos/observation.images.<cam>/chunk-000/file-000.mp4   H.264 (or AV1), the file's episodes back to back
//!   .collect/                                   ours: staged episodes and the resume ledger
//! ```
//!
//! Files hold [`EPISODES_PER_FILE`] episodes; a chunk holds 1000 files (LeRobot's
//! `chunks_size`). Each file `k` of data, of every camera's video and of `meta/episodes` holds
//! the same episodes, so an episode's `data/file_index` and `videos/<key>/file_index` agree.
//!
//! **Resuming.** Episodes run in parallel and finish in any order, and the global `index`,
//! `episode_index` and video offsets are only known once an episode's place is fixed. So a kept
//! episode is first *staged* ([`EpisodeRecorder::finish`]: its rows as JSON, its video samples
//! per camera, encoded while it ran), and [`LeRobotDataset`] on the collecting thread appends
//! staged episodes as new files, [`EPISODES_PER_FILE`] at a time and the rest at the end of the
//! run, then records them in `.collect/episodes.jsonl` and rewrites `info.json`, `stats.json`
//! and `tasks.parquet` from that ledger. Files are written as `*.partial` and renamed; an
//! interrupted run leaves staged episodes (kept by the next run) or an unrecorded file (written
//! again under the same name), never a half-written file that the metadata points to.

mod dataset;
mod episode;
mod ledger;
mod meta;
mod stats;
mod tables;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub use dataset::LeRobotDataset;
pub use episode::EpisodeRecorder;

/// Frames per second: one row per control step (10 Hz).
pub const FPS: u32 = 10;

/// Episodes per data/video file: ~1–3 MB of video per camera and episode keeps a file near
/// LeRobot's 100–200 MB default file sizes.
pub const EPISODES_PER_FILE: usize = 100;

/// LeRobot's `DEFAULT_CHUNK_SIZE`: files per chunk folder.
pub(crate) const CHUNKS_SIZE: usize = 1000;

/// A camera as the dataset records it: `observation.images.<name>`, `width`×`height` RGB.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CameraSpec {
    pub name: String,
    pub width: u32,
    pub height: u32,
}

impl CameraSpec {
    pub(crate) fn key(&self) -> String {
        format!("observation.images.{}", self.name)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum LeRobotError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("Parquet: {0}")]
    Parquet(#[from] parquet::errors::ParquetError),
    #[error("Arrow: {0}")]
    Arrow(#[from] arrow_schema::ArrowError),
    #[error("{0}")]
    Video(#[from] crate::video::VideoError),
    #[error("{path}: {message}")]
    Json { path: PathBuf, message: String },
    #[error("{0}")]
    Frame(String),
    #[error("{0}")]
    Mismatch(String),
}

pub(crate) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> LeRobotError + '_ {
    move |source| LeRobotError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Write `path` through `path.partial` and a rename, so a reader never sees half a file.
pub(crate) fn write_atomic(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), LeRobotError>,
) -> Result<(), LeRobotError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    }
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = PathBuf::from(tmp);
    write(&tmp)?;
    std::fs::rename(&tmp, path).map_err(io_err(path))
}
