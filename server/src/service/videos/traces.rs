//! Episode traces on disk (docs/contest/video.md): stored by content beside the videos
//! (`<dir>/traces/<aa>/<sha256>.json.gz`), linked to (run, episode) in `episode_traces`, served
//! to whoever may see the episode's video, and deleted once no row names them. Placing,
//! linking and deleting a trace file take the videos' file lock (`turn`), so a file is never
//! deleted between an upload of the same bytes placing and linking it.

use std::path::{Path, PathBuf};

use super::{Complete, UploadError, trace_path};
use crate::error::ServiceError;
use crate::service::video_budget::Booking;
use crate::service::{AppState, Caller, now_ms};
use crate::store;

/// A stored trace to serve (gzipped JSON).
#[derive(Debug, Clone)]
pub(crate) struct StoredTrace {
    pub path: PathBuf,
    pub sha256: String,
}

impl AppState {
    /// The trace of one episode of a submission's latest run, for whoever may see its video.
    pub(crate) async fn episode_trace(
        &self,
        caller: &Caller,
        id: i64,
        episode_key: &str,
    ) -> Result<StoredTrace, ServiceError> {
        let not_found =
            || ServiceError::not_found(format!("a trace of episode {episode_key:?} of submission {id}"));
        let (dir, run) = self.media_run(caller, id).await?.ok_or_else(not_found)?;
        let sha256 = store::traces::trace(self.read_pool(), run, episode_key)
            .await?
            .ok_or_else(not_found)?;
        let path = trace_path(&dir, &sha256);
        match tokio::fs::try_exists(&path).await.unwrap_or(false) {
            true => Ok(StoredTrace { path, sha256 }),
            false => Err(not_found()),
        }
    }

    /// Move a finished trace upload into place and link it to `(run, key)`; a replaced file no
    /// row names any more is deleted. Returns the sha256 and size.
    pub(crate) async fn store_trace(
        &self,
        dir: &Path,
        booking: Booking,
        run: i64,
        key: &str,
        file: Complete,
    ) -> Result<(String, u64), UploadError> {
        let (sha, bytes) = (file.sha256.clone(), file.bytes);
        let _turn = self.file_turn().await;
        file.place_at(trace_path(dir, &sha)).await?;
        let row = store::videos::Row {
            run,
            key,
            team: booking.team(),
            now: now_ms(),
        };
        let replaced = store::traces::link(self.pool(), row, &sha, bytes)
            .await
            .map_err(ServiceError::from)?;
        // Linked: the row counts against the budgets from now on.
        drop(booking);
        self.delete_traces_locked(dir, replaced.into_iter().collect())
            .await;
        Ok((sha, bytes))
    }

    /// Delete the trace files no row names (a process killed between placing and linking one);
    /// at start, with the videos' sweep. Returns how many were deleted.
    pub(super) async fn sweep_unlinked_traces(&self, dir: &Path) -> Result<usize, ServiceError> {
        let mut deleted = 0;
        for sub in super::subdirs(&dir.join("traces")).await? {
            let mut unlinked = Vec::new();
            let mut files = tokio::fs::read_dir(&sub).await.map_err(super::io)?;
            while let Some(f) = files.next_entry().await.map_err(super::io)? {
                let name = f.file_name();
                let Some(sha) = name.to_str().and_then(|n| n.strip_suffix(".json.gz")) else {
                    continue;
                };
                if !store::traces::linked(self.read_pool(), sha).await? {
                    unlinked.push(sha.to_string());
                }
            }
            deleted += self.delete_unlinked_traces(dir, unlinked).await;
        }
        Ok(deleted)
    }

    /// Delete the trace files `shas` that no row names (checked again under the file lock).
    pub(crate) async fn delete_unlinked_traces(&self, dir: &Path, shas: Vec<String>) -> usize {
        let _turn = self.file_turn().await;
        self.delete_traces_locked(dir, shas).await
    }

    /// [`Self::delete_unlinked_traces`], for a caller holding the file lock.
    pub(crate) async fn delete_traces_locked(&self, dir: &Path, shas: Vec<String>) -> usize {
        let mut deleted = 0;
        for sha in shas {
            if !matches!(store::traces::linked(self.pool(), &sha).await, Ok(false)) {
                continue;
            }
            match tokio::fs::remove_file(trace_path(dir, &sha)).await {
                Ok(()) => deleted += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => tracing::warn!(sha256 = %sha, error = %e, "cannot delete an unlinked trace"),
            }
        }
        deleted
    }
}
