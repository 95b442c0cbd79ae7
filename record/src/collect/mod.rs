//! Expert trajectory collection (`kitchen-r collect`; paper, Logging, Monitoring and
//! Customization and Randomization modules).
//!
//! Episode `i` takes dev instruction `i mod n` with a seed drawn from `(seed, i)`: the robot start
//! and background objects from the episode-configuration generator, then (with `randomise`, the
//! default) the paper's randomisation of `kitchen_r_sim::randomise`: key-object poses, colours,
//! textures, light, background, robot start, each as switched in `configs/episodes.toml`
//! `[randomise]`. With a batch
//! ([`CollectOptions::batch`], `collect --episodes-file`) episode `i` is the batch's `i`-th
//! configuration, run exactly as saved. The oracle expert drives it
//! closed-loop, one action per query, through the evaluation runner; every control step is
//! recorded (the chosen cameras' RGB and, unless turned off, depth; LiDAR, odometry, IMU, TF,
//! cmd_vel, the action) to MCAP, HDF5 and/or a LeRobotDataset by [`crate::mcap_ros2`],
//! [`crate::hdf5_aloha`] and [`crate::lerobot`]. An episode that trips a monitor of
//! `configs/collect.toml`, fails a task, or fails the simulator's preflight collider check is
//! discarded: its files are removed and the reason counted.
//!
//! Output directory: `ep00000.mcap`, `ep00000.hdf5`, ... written as `*.partial` and renamed when
//! complete, plus `manifest.jsonl` (one line per finished episode, kept or discarded), plus the
//! LeRobotDataset under `lerobot/` (its own resumable layout, see [`crate::lerobot`]). A rerun
//! skips episodes whose final files exist, so an interrupted collection resumes.

mod config;
mod hook;
mod run;
mod sensors;

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

pub use crate::hdf5_aloha::DepthUnit;
pub use config::{CollectConfig, RateConfig};
pub use run::collect;

/// The sensors a run with `opts` simulates (the configured ones, less the cameras `--cameras`
/// leaves out): the topics its live view advertises.
pub fn live_sensors(opts: &CollectOptions) -> Result<kitchen_r_sim::SensorsConfig, CollectError> {
    sensors::sensors(opts)
}

#[derive(Debug, thiserror::Error)]
pub enum CollectError {
    #[error("collect config: {0}")]
    Config(String),
    #[error("{0}")]
    Eval(#[from] kitchen_r_episode::eval::EvalError),
    #[error("{0}")]
    Sim(#[from] kitchen_r_sim::SimError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("a collection thread panicked")]
    Panicked,
    #[error("LeRobot dataset: {0}")]
    LeRobot(#[from] crate::lerobot::LeRobotError),
}

/// Which files each episode gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Formats {
    pub mcap: bool,
    pub hdf5: bool,
    /// Rows and video frames in the LeRobotDataset v3.0 under `<out>/lerobot/`.
    pub lerobot: bool,
}

impl std::str::FromStr for Formats {
    type Err = String;
    /// A comma-separated list of `mcap`, `hdf5` and `lerobot`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut f = Formats {
            mcap: false,
            hdf5: false,
            lerobot: false,
        };
        for part in s.split(',').map(str::trim) {
            match part {
                "mcap" => f.mcap = true,
                "hdf5" => f.hdf5 = true,
                "lerobot" => f.lerobot = true,
                other => {
                    return Err(format!(
                        "unknown format {other:?} (accepted: mcap, hdf5, lerobot)"
                    ));
                }
            }
        }
        Ok(f)
    }
}

impl Formats {
    /// The per-episode files' extensions (the LeRobotDataset has no file per episode).
    pub(crate) fn extensions(self) -> Vec<&'static str> {
        [(self.mcap, "mcap"), (self.hdf5, "hdf5")]
            .into_iter()
            .filter_map(|(on, e)| on.then_some(e))
            .collect()
    }
}

#[derive(Debug, Clone)]
pub struct CollectOptions {
    /// Episodes to collect (ignored when `batch` is given: then its length).
    pub episodes: usize,
    pub out: PathBuf,
    pub formats: Formats,
    pub jobs: usize,
    pub seed: u64,
    pub config: CollectConfig,
    /// Cameras and LiDAR to record; `None` = `configs/sensors.toml`.
    pub sensors: Option<kitchen_r_sim::SensorsConfig>,
    /// Names of the cameras to record, a subset of the sensors' (`None` = all of them).
    pub cameras: Option<Vec<String>>,
    /// Depth images: `None` records none (MCAP, HDF5); else HDF5's unit (MCAP stays `32FC1`).
    pub depth: Option<DepthUnit>,
    /// Exactly these episode configurations (`collect --episodes-file`, a batch written by
    /// `kitchen_r_sim::episode::save_batch`) instead of drawing from the dev instructions.
    pub batch: Option<Vec<kitchen_r_sim::EpisodeConfig>>,
    /// Episodes per LeRobotDataset data/video file ([`crate::lerobot::EPISODES_PER_FILE`]).
    pub lerobot_episodes_per_file: usize,
    /// The LeRobotDataset's video codec; `None`: the dataset's own when appending, else H.264.
    pub video_codec: Option<crate::video::Codec>,
    /// Grasp mode of every episode (`collect --grasp`); `None` = `configs/sim.toml`'s.
    pub grasp: Option<kitchen_r_core::GraspMode>,
    /// Draw an indicatif progress bar on stderr (hidden anyway when stderr is not a terminal).
    pub progress: bool,
    /// Publish the episodes live (`collect --foxglove`/`--ros2`, [`crate::live`]): one at a
    /// time, best effort, never changing what is recorded.
    pub live: Option<crate::live::LiveQueue>,
}

impl CollectOptions {
    /// `episodes` dev episodes into `out` as MCAP and HDF5, one job, seed 0, the default
    /// thresholds and sensors, every camera, millimetre depth; set fields to change that.
    pub fn new(out: impl Into<PathBuf>, episodes: usize) -> CollectOptions {
        CollectOptions {
            episodes,
            out: out.into(),
            formats: Formats {
                mcap: true,
                hdf5: true,
                lerobot: false,
            },
            jobs: 1,
            seed: 0,
            config: CollectConfig::default(),
            sensors: None,
            cameras: None,
            depth: Some(DepthUnit::default()),
            batch: None,
            lerobot_episodes_per_file: crate::lerobot::EPISODES_PER_FILE,
            video_codec: None,
            grasp: None,
            progress: false,
            live: None,
        }
    }

    /// How many episodes the run covers.
    pub(crate) fn count(&self) -> usize {
        self.batch.as_ref().map_or(self.episodes, Vec::len)
    }
}

/// One `manifest.jsonl` line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ManifestEntry {
    pub index: usize,
    pub episode_id: String,
    pub instruction_id: String,
    pub seed: u64,
    /// The grasp mode the episode ran in (manifests written before it existed: abstract).
    #[serde(default)]
    pub grasp_mode: kitchen_r_core::GraspMode,
    pub kept: bool,
    /// The monitor or failure that discarded the episode.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason_kind: Option<String>,
    pub frames: usize,
    pub sim_time: f64,
    pub wall_s: f64,
    pub files: Vec<String>,
}

/// What a collection run did.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CollectSummary {
    pub requested: usize,
    pub kept: usize,
    /// Episodes whose files already existed (resume).
    pub skipped: usize,
    /// Discarded episodes by reason kind.
    pub discarded: BTreeMap<String, usize>,
    pub frames: usize,
    pub wall_s: f64,
    /// Episodes run (kept + discarded) per wall-clock minute.
    pub episodes_per_min: f64,
}
