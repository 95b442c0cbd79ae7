//! Episode videos (issue #15): stored by content, linked to (run, episode), served to whoever may
//! see the episode, and deleted after `[video] retention_days`.
//!
//! Storage policy: a file is named by the sha256 of its bytes, `<dir>/<aa>/<sha256>.mp4`, so
//! identical uploads are stored once. An upload is written to `<dir>/tmp/` while hashed and
//! moved into place at the end; a stream that breaks off, runs past its announced size or past
//! `max_bytes` leaves nothing behind. Rows (`episode_videos`) say which file shows which episode;
//! the sweep deletes rows past retention, then every file no row names any more.
//!
//! Who sees a video is the path plot's rule (`AppState::episode_plot`), widened for the
//! organiser: a team sees its own dev-split policy submissions' videos; the organiser sees every
//! video, test split included. Test-split videos are recorded and stored, but a participant
//! never gets them (they show the hidden plan being executed). Anything else is 404.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use kitchen_r_core::dataset::Split;
use sha2::{Digest, Sha256};
use tokio::io::AsyncWriteExt;

use crate::error::ServiceError;
use crate::service::{AppState, Caller, now_ms};
use crate::states::SubmissionKind;
use crate::store;

/// How often the retention sweep runs.
const SWEEP_EVERY: Duration = Duration::from_secs(3600);
const DAY_MS: i64 = 86_400_000;

/// Where the file with hash `sha256` lives under `dir`.
pub(crate) fn file_path(dir: &Path, sha256: &str) -> PathBuf {
    dir.join(&sha256[..2.min(sha256.len())])
        .join(format!("{sha256}.mp4"))
}

/// Why an upload was not stored.
#[derive(Debug, thiserror::Error)]
pub(crate) enum UploadError {
    #[error("the video is {got} bytes, over the announced {announced}")]
    Longer { got: u64, announced: u64 },
    #[error("the stream ended after {got} of {announced} bytes")]
    Short { got: u64, announced: u64 },
    #[error("the video is {size} bytes, over the server's limit of {limit} (`[video] max_bytes`)")]
    TooLarge { size: u64, limit: u64 },
    #[error("storing the video: {0}")]
    Io(#[from] std::io::Error),
}

/// An upload being written: hashed as it comes, moved into place by [`Incoming::finish`], and
/// removed if dropped before.
pub(crate) struct Incoming {
    tmp: PathBuf,
    file: Option<tokio::fs::File>,
    hash: Sha256,
    got: u64,
    announced: u64,
}

static UPLOADS: AtomicU64 = AtomicU64::new(0);

impl Incoming {
    /// Start an upload of `announced` bytes into `dir`, refusing one over `limit` at once.
    pub(crate) async fn start(dir: &Path, announced: u64, limit: u64) -> Result<Incoming, UploadError> {
        if announced > limit {
            return Err(UploadError::TooLarge {
                size: announced,
                limit,
            });
        }
        let tmp_dir = dir.join("tmp");
        tokio::fs::create_dir_all(&tmp_dir).await?;
        let n = UPLOADS.fetch_add(1, Ordering::Relaxed);
        let tmp = tmp_dir.join(format!("{}-{}-{n}.part", std::process::id(), now_ms()));
        let file = tokio::fs::File::create(&tmp).await?;
        Ok(Incoming {
            tmp,
            file: Some(file),
            hash: Sha256::new(),
            got: 0,
            announced,
        })
    }

    pub(crate) async fn write(&mut self, data: &[u8]) -> Result<(), UploadError> {
        self.got += data.len() as u64;
        if self.got > self.announced {
            return Err(UploadError::Longer {
                got: self.got,
                announced: self.announced,
            });
        }
        self.hash.update(data);
        if let Some(f) = &mut self.file {
            f.write_all(data).await?;
        }
        Ok(())
    }

    /// Check the size, and move the file to its content name (kept as it is when that file is
    /// there already). Returns the sha256 and the size.
    pub(crate) async fn finish(mut self, dir: &Path) -> Result<(String, u64), UploadError> {
        if self.got != self.announced {
            return Err(UploadError::Short {
                got: self.got,
                announced: self.announced,
            });
        }
        if let Some(mut f) = self.file.take() {
            f.flush().await?;
            f.sync_all().await?;
        }
        let sha = hex::encode(std::mem::take(&mut self.hash).finalize());
        let dest = file_path(dir, &sha);
        if let Some(parent) = dest.parent() {
            tokio::fs::create_dir_all(parent).await?;
        }
        if tokio::fs::try_exists(&dest).await? {
            tokio::fs::remove_file(&self.tmp).await?;
        } else {
            tokio::fs::rename(&self.tmp, &dest).await?;
        }
        self.tmp = PathBuf::new();
        Ok((sha, self.got))
    }
}

impl Drop for Incoming {
    fn drop(&mut self) {
        if !self.tmp.as_os_str().is_empty() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// A stored video to serve.
#[derive(Debug, Clone)]
pub(crate) struct StoredVideo {
    pub path: PathBuf,
    pub sha256: String,
}

impl AppState {
    /// The video directory, when videos are on and have somewhere to live.
    pub(crate) fn video_dir(&self) -> Option<PathBuf> {
        let cfg = self.config();
        cfg.video.enabled.then(|| cfg.video.directory(&cfg.db)).flatten()
    }

    /// Link a finished upload to its episode.
    pub(crate) async fn link_video(
        &self,
        run: i64,
        key: &str,
        sha256: &str,
        bytes: u64,
    ) -> Result<(), ServiceError> {
        store::videos::link(self.pool(), run, key, sha256, bytes, now_ms()).await?;
        Ok(())
    }

    /// The video of one episode of a submission's latest run; see the module doc for who may
    /// see it. Anything else is not found.
    pub(crate) async fn episode_video(
        &self,
        caller: &Caller,
        id: i64,
        episode_key: &str,
    ) -> Result<StoredVideo, ServiceError> {
        let not_found =
            || ServiceError::not_found(format!("a video of episode {episode_key:?} of submission {id}"));
        let visible = self.visible_submission(caller, id).await?;
        let dir = self.video_dir().ok_or_else(not_found)?;
        // Test-split videos are the organiser's alone.
        let (sub, _) = visible
            .filter(|(s, organiser)| {
                s.kind == SubmissionKind::Policy && (*organiser || s.split == Split::Dev.as_str())
            })
            .ok_or_else(not_found)?;
        let run = store::latest_run(self.read_pool(), sub.id)
            .await?
            .ok_or_else(not_found)?;
        let (sha256, _) = store::videos::video(self.read_pool(), run.episodes_run(), episode_key)
            .await?
            .ok_or_else(not_found)?;
        let path = file_path(&dir, &sha256);
        if !tokio::fs::try_exists(&path).await.unwrap_or(false) {
            return Err(not_found());
        }
        Ok(StoredVideo { path, sha256 })
    }

    /// The episode keys of `run` with a video to show (none when videos are off).
    pub(crate) async fn video_keys(&self, run: i64) -> Result<Vec<String>, ServiceError> {
        if self.video_dir().is_none() {
            return Ok(Vec::new());
        }
        Ok(store::videos::keys(self.read_pool(), run).await?)
    }

    /// Delete the videos linked before `now - retention_days` and the files left unlinked.
    /// Returns how many files were deleted.
    pub(crate) async fn sweep_videos(&self, now: i64) -> Result<usize, ServiceError> {
        let cfg = &self.config().video;
        let Some(dir) = cfg.directory(&self.config().db) else {
            return Ok(0);
        };
        if cfg.retention_days == 0 {
            return Ok(0);
        }
        let before = now - i64::from(cfg.retention_days) * DAY_MS;
        let orphans = store::videos::expire(self.pool(), before).await?;
        let mut deleted = 0;
        for sha in orphans {
            // An upload of the same bytes may have linked the file again meanwhile.
            if store::videos::linked(self.pool(), &sha).await? {
                continue;
            }
            match tokio::fs::remove_file(file_path(&dir, &sha)).await {
                Ok(()) => deleted += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => tracing::warn!(sha256 = %sha, error = %e, "cannot delete an expired video"),
            }
        }
        Ok(deleted)
    }
}

/// Runs the retention sweep at start and every hour until shutdown.
pub(crate) async fn sweeper(state: AppState, mut stop: tokio::sync::watch::Receiver<bool>) {
    let mut tick = tokio::time::interval(SWEEP_EVERY);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = tick.tick() => {}
            _ = stop.wait_for(|s| *s) => return,
        }
        match state.sweep_videos(now_ms()).await {
            Ok(0) => {}
            Ok(n) => tracing::info!(deleted = n, "expired episode videos deleted"),
            Err(e) => tracing::error!(error = %e, "video retention sweep failed; retrying next hour"),
        }
    }
}

#[cfg(test)]
mod tests;
