//! What the `.collect/episodes.jsonl` ledger records of each episode, the features every
//! episode must share, and where a global file number lies. A file of its own because the
//! dataset ([`super::dataset`]) writes these and the metadata ([`super::meta`]) is rebuilt from
//! them: held in `dataset`, they made `dataset` and `meta` import each other (docs/contributing.md,
//! import circles).

use serde::{Deserialize, Serialize};

use super::episode::{StagedEpisode, codec_before_h264};
use super::stats::FeatureStats;
use super::{CHUNKS_SIZE, CameraSpec};
use crate::video::Codec;

/// One ledger line: an episode in the dataset and everything the metadata is rebuilt from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct EpisodeRecord {
    pub episode_index: usize,
    pub collect_index: usize,
    pub episode_id: String,
    pub scene: String,
    pub instruction: String,
    pub tasks: Vec<String>,
    pub length: usize,
    /// Global file number: chunk `file / 1000`, file `file % 1000`.
    pub file: usize,
    pub from_index: usize,
    pub from_timestamp: f64,
    pub stats: Vec<(String, FeatureStats)>,
}

/// The features every episode must share (checked when a staged episode is appended).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(super) struct Spec {
    /// Numeric features: key and per-dimension names.
    pub columns: Vec<(String, Vec<String>)>,
    pub cameras: Vec<CameraSpec>,
    /// The videos' codec (a dataset collected before H.264 existed is AV1).
    #[serde(default = "codec_before_h264")]
    pub codec: Codec,
}

impl Spec {
    pub(super) fn of(e: &StagedEpisode) -> Spec {
        Spec {
            columns: e
                .columns
                .iter()
                .map(|c| (c.key.clone(), c.names.clone()))
                .collect(),
            cameras: e.cameras.clone(),
            codec: e.codec,
        }
    }
}

/// A global file number as (chunk, file in the chunk).
pub(super) fn chunk_file(file: usize) -> (usize, usize) {
    (file / CHUNKS_SIZE, file % CHUNKS_SIZE)
}
