//! Episode videos (docs/contest/video.md): stored by content, linked to (run, episode), served to
//! whoever may see the episode, and deleted after `[video] retention_days` or when a storage budget
//! needs the room.
//!
//! Storage policy: a file is named by the sha256 of its bytes, `<dir>/<aa>/<sha256>.mp4`, so
//! identical uploads are stored once. An upload is written to `<dir>/tmp/` while hashed and
//! moved into place at the end; a stream that breaks off, runs past its announced size or past
//! `max_bytes` leaves nothing behind, and what a killed process left in `tmp/` is removed at the
//! next start. Rows (`episode_videos`) say which file shows which episode; a file is deleted as
//! soon as no row names it: when its link is replaced, when its video is evicted to keep a
//! budget (`crate::service::video_budget`), and by the sweep, which deletes rows past retention.
//! The server is the only writer of its video directory (one replica).
//!
//! Videos on demand: workers upload each episode's trace instead of its video
//! (`<dir>/traces/<aa>/<sha256>.json.gz`, rows in `episode_traces`, the same retention), and the
//! video is rendered from it by a worker when first asked for ([`traces`],
//! `crate::service::renders`); the rendered file is then stored and linked as any video.
//!
//! Who sees a video (or a trace) is the path plot's rule (`AppState::episode_plot`), widened for the
//! organiser: a team sees its own dev-split policy submissions' videos; the organiser sees every
//! video, test split included. Test-split videos are recorded and stored, but a participant
//! never gets them (they show the hidden plan being executed). Anything else is 404.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use kitchen_r_core::dataset::Split;

use super::{AppState, Caller, now_ms};
use crate::error::ServiceError;
use crate::states::SubmissionKind;
use crate::store;

/// How often the retention sweep runs.
const SWEEP_EVERY: Duration = Duration::from_secs(3600);
const DAY_MS: i64 = 86_400_000;

pub(crate) use incoming::{Complete, Incoming, UploadError, file_path, trace_path};
use incoming::{clear_partial, tmp_dir};

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

    /// The stored video of one episode of a submission's latest run, for whoever may see it;
    /// anything else (no video stored yet, too) is not found. The HTTP routes ask
    /// `AppState::video_or_render`, which also renders.
    #[cfg(test)]
    pub(crate) async fn episode_video(
        &self,
        caller: &Caller,
        id: i64,
        episode_key: &str,
    ) -> Result<StoredVideo, ServiceError> {
        let not_found =
            || ServiceError::not_found(format!("a video of episode {episode_key:?} of submission {id}"));
        let (dir, run) = self.media_run(caller, id).await?.ok_or_else(not_found)?;
        self.stored_video(&dir, run, episode_key)
            .await?
            .ok_or_else(not_found)
    }

    /// The stored video of `(run, key)`, when its file is there.
    pub(crate) async fn stored_video(
        &self,
        dir: &Path,
        run: i64,
        key: &str,
    ) -> Result<Option<StoredVideo>, ServiceError> {
        let Some((sha256, _)) = store::videos::video(self.read_pool(), run, key).await? else {
            return Ok(None);
        };
        let path = file_path(dir, &sha256);
        match tokio::fs::try_exists(&path).await.unwrap_or(false) {
            true => Ok(Some(StoredVideo { path, sha256 })),
            false => Ok(None),
        }
    }

    /// The video directory and the run whose episodes' media (video, trace) `caller` may have
    /// of submission `id` (see the module doc); `None` for anything else.
    pub(crate) async fn media_run(
        &self,
        caller: &Caller,
        id: i64,
    ) -> Result<Option<(PathBuf, i64)>, ServiceError> {
        let visible = self.visible_submission(caller, id).await?;
        let Some(dir) = self.video_dir() else {
            return Ok(None);
        };
        // Test-split media are the organiser's alone.
        let Some((sub, _)) = visible.filter(|(s, organiser)| {
            s.kind == SubmissionKind::Policy && (*organiser || s.split == Split::Dev.as_str())
        }) else {
            return Ok(None);
        };
        let run = store::latest_run(self.read_pool(), sub.id).await?;
        Ok(run.map(|r| (dir, r.episodes_run())))
    }

    /// The episodes of `run` with a video row or a removed trace (none when videos are off):
    /// `None` for a stored video, else the note saying why it is gone.
    pub(crate) async fn video_keys(&self, run: i64) -> Result<HashMap<String, Option<String>>, ServiceError> {
        if self.video_dir().is_none() {
            return Ok(HashMap::new());
        }
        let mut keys: HashMap<String, Option<String>> = store::videos::keys(self.read_pool(), run)
            .await?
            .into_iter()
            .collect();
        // A trace removed to keep a budget: its video cannot come back, which says more than a
        // removed video's note (rendered again from the trace when asked for).
        for (key, note) in store::traces::notes(self.read_pool(), run).await? {
            // A stored video (`Some(None)`) stays watchable.
            if !matches!(keys.get(&key), Some(None)) {
                keys.insert(key, Some(note));
            }
        }
        Ok(keys)
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
        let traces = store::traces::expire(self.pool(), before).await?;
        Ok(self.delete_unlinked(&dir, orphans).await + self.delete_unlinked_traces(&dir, traces).await)
    }

    /// Delete the stored files that no row names: left by a process killed between placing a
    /// file and linking it, or by a server before this one that kept replaced files. Run once
    /// at start, in the background. Returns how many were deleted.
    pub(crate) async fn sweep_unlinked_files(&self) -> Result<usize, ServiceError> {
        let Some(dir) = self.config().video.directory(&self.config().db) else {
            return Ok(0);
        };
        let mut deleted = 0;
        for sub in subdirs(&dir).await? {
            let mut unlinked = Vec::new();
            let mut files = tokio::fs::read_dir(&sub).await.map_err(io)?;
            while let Some(f) = files.next_entry().await.map_err(io)? {
                let name = f.file_name();
                let Some(sha) = name.to_str().and_then(|n| n.strip_suffix(".mp4")) else {
                    continue;
                };
                if !store::videos::linked(self.read_pool(), sha).await? {
                    unlinked.push(sha.to_string());
                }
            }
            deleted += self.delete_unlinked(&dir, unlinked).await;
        }
        Ok(deleted + self.sweep_unlinked_traces(&dir).await?)
    }
}

/// The `<aa>` folders of the video directory (not `tmp/`).
async fn subdirs(dir: &Path) -> Result<Vec<PathBuf>, ServiceError> {
    let mut out = Vec::new();
    let mut entries = match tokio::fs::read_dir(dir).await {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(out),
        Err(e) => return Err(io(e)),
    };
    while let Some(e) = entries.next_entry().await.map_err(io)? {
        let name = e.file_name();
        let two_hex = name.len() == 2
            && name
                .to_str()
                .is_some_and(|n| n.bytes().all(|b| b.is_ascii_hexdigit()));
        if two_hex && e.file_type().await.map_err(io)?.is_dir() {
            out.push(e.path());
        }
    }
    Ok(out)
}

fn io(e: std::io::Error) -> ServiceError {
    ServiceError::Internal(anyhow::Error::new(e).context("reading the video directory"))
}

/// Before the server listens: remove the partial uploads a killed process left in `tmp/`.
pub(crate) async fn clear_partial_uploads(state: &AppState) -> anyhow::Result<()> {
    let Some(dir) = state.config().video.directory(&state.config().db) else {
        return Ok(());
    };
    let n = clear_partial(&dir)
        .await
        .with_context(|| format!("clearing partial video uploads in {}", tmp_dir(&dir).display()))?;
    if n > 0 {
        tracing::info!(removed = n, "partial video uploads of an earlier process removed");
    }
    Ok(())
}

/// Deletes unlinked files once, then runs the retention sweep at start and every hour until
/// shutdown.
pub(crate) async fn sweeper(state: AppState, mut stop: tokio::sync::watch::Receiver<bool>) {
    match state.sweep_unlinked_files().await {
        Ok(0) => {}
        Ok(n) => tracing::info!(deleted = n, "video files no episode links deleted"),
        Err(e) => tracing::error!(error = %e, "sweeping unlinked video files failed"),
    }
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
        state.record_stored_video_bytes().await;
    }
}

pub(crate) mod incoming;
#[cfg(test)]
pub(crate) mod tests;
mod traces;
