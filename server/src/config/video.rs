//! `[video]`: episode videos, rendered on demand from traces (docs/contest/video.md). The
//! organiser decides centrally: the setting travels to the workers with every leased job
//! (`EpisodeSpec.record_video`, `video_on_demand`, `video_max_bytes`).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::ConfigError;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VideoConfig {
    /// Workers record the trace of every online dev-split episode and upload it; its video is
    /// rendered from it by a worker when first asked for. false: nothing is recorded, and stored
    /// videos are no longer served.
    pub enabled: bool,
    /// Record test-split episodes' traces too (their videos shown to the organiser only). Off by
    /// default: a test run is the contest's largest, run by every team at the deadline.
    pub test_split: bool,
    /// Delete videos older than this many days (a sweep runs at start and every hour); 0 keeps
    /// them forever.
    pub retention_days: u32,
    /// Largest video (or gzipped trace) file accepted, bytes (workers do not upload a larger one).
    pub max_bytes: u64,
    /// Most bytes of stored videos and traces one team's episodes may link; an upload past it
    /// first removes that team's oldest videos, then its oldest traces (their episodes say so
    /// where the video was). Env: `KITCHEN_R_VIDEO_TEAM_MAX_BYTES`.
    pub team_max_bytes: u64,
    /// Most bytes of stored videos and traces of all teams together; past it only teams over
    /// their fair share (`min(team_max_bytes, total_max_bytes / teams storing files)`) lose their
    /// oldest files, and when none is over, the upload is refused (a render waits). Traces of
    /// ranked test runs are never removed. Env: `KITCHEN_R_VIDEO_TOTAL_MAX_BYTES`.
    pub total_max_bytes: u64,
    /// Which videos workers render before anyone asks, whenever no evaluation job and no
    /// asked-for render waits: `failed` (episodes with a failed task: the ones people open, and
    /// the longest to render), `all`, or `none` (only on request).
    pub prerender: Prerender,
    /// Where the files are stored (`<aa>/<sha256>.mp4`); empty means `videos/` beside the
    /// database file (no videos with an in-memory database).
    pub dir: PathBuf,
}

/// `[video] prerender`: see [`VideoConfig::prerender`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Prerender {
    None,
    Failed,
    All,
}

impl Default for VideoConfig {
    fn default() -> Self {
        VideoConfig {
            enabled: true,
            test_split: false,
            retention_days: 30,
            max_bytes: 64 << 20,
            // A failing policy's dev episode makes 1–6.5 MB of video (docs/contest/video.md):
            // 2 GiB keeps a team's last two full dev runs of the worst such policy.
            team_max_bytes: 2 << 30,
            // Fits the shipped 10 Gi volume (deploy/k8s/base) with room for the database.
            total_max_bytes: 8 << 30,
            prerender: Prerender::Failed,
            dir: PathBuf::new(),
        }
    }
}

impl VideoConfig {
    pub(super) fn validate(&self) -> Result<(), ConfigError> {
        if !(1024..=(1 << 30)).contains(&self.max_bytes) {
            return Err(ConfigError::Invalid {
                key: "video.max_bytes",
                message: "must be between 1 KiB and 1 GiB".into(),
            });
        }
        // Each budget must hold at least one file of the one below it, or an upload that
        // `max_bytes` accepts could never be stored.
        if self.team_max_bytes < self.max_bytes {
            return Err(ConfigError::Invalid {
                key: "video.team_max_bytes",
                message: format!(
                    "{} is less than `video.max_bytes` ({}): a team's budget must hold at least its largest video",
                    self.team_max_bytes, self.max_bytes
                ),
            });
        }
        if self.total_max_bytes < self.team_max_bytes {
            return Err(ConfigError::Invalid {
                key: "video.total_max_bytes",
                message: format!(
                    "{} is less than `video.team_max_bytes` ({}): the total must hold at least one team's budget",
                    self.total_max_bytes, self.team_max_bytes
                ),
            });
        }
        Ok(())
    }

    /// The directory videos live in for a server whose database is `db`; `None` when there is
    /// nowhere to put them (an in-memory database and no `dir`).
    pub fn directory(&self, db: &str) -> Option<PathBuf> {
        if !self.dir.as_os_str().is_empty() {
            return Some(self.dir.clone());
        }
        Some(super::beside_database(db)?.join("videos"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn videos_live_beside_the_database_unless_a_dir_is_given() {
        let v = VideoConfig::default();
        assert_eq!(
            v.directory("sqlite://data/kitchen-r.db"),
            Some(PathBuf::from("data/videos"))
        );
        assert_eq!(
            v.directory("sqlite:/srv/k.db?mode=rwc"),
            Some(PathBuf::from("/srv/videos"))
        );
        assert_eq!(v.directory("sqlite::memory:"), None);
        let v = VideoConfig {
            dir: "/v".into(),
            ..VideoConfig::default()
        };
        assert_eq!(v.directory("sqlite::memory:"), Some(PathBuf::from("/v")));
        assert!(VideoConfig { max_bytes: 5, ..v }.validate().is_err());
    }

    #[test]
    fn budgets_must_nest_max_bytes_within_team_within_total() {
        let v = VideoConfig::default();
        assert_eq!(v.validate().map_err(|e| e.to_string()), Ok(()));
        let key = |v: VideoConfig| match v.validate() {
            Err(ConfigError::Invalid { key, message }) => (key, message),
            other => panic!("{other:?}"),
        };
        let (k, m) = key(VideoConfig {
            team_max_bytes: v.max_bytes - 1,
            ..v.clone()
        });
        assert_eq!(k, "video.team_max_bytes");
        assert!(m.contains("video.max_bytes"), "{m}");
        let (k, m) = key(VideoConfig {
            total_max_bytes: v.team_max_bytes - 1,
            ..v.clone()
        });
        assert_eq!(k, "video.total_max_bytes");
        assert!(m.contains("video.team_max_bytes"), "{m}");
    }
}
