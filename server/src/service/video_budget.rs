//! Bounded media storage (docs/contest/video.md, budgets): per-team and total byte budgets
//! (`[video] team_max_bytes`, `total_max_bytes`) over videos and traces together, and no file left
//! on disk that nothing links.
//!
//! Policy: an upload's announced size (a video's or a trace's) is booked before a byte is
//! written; what to evict for it, fairly between teams, is `crate::store::budget`'s rule. A
//! removed file keeps its row with a note that the episode shows where the video was.
//!
//! Concurrency: this server is its video directory's only writer (one replica, `deploy/`), so
//! uploads in flight are booked in memory, and one lock (`turn`) orders every step that decides
//! a file's fate: booking (with its evictions), placing a file and linking it, and deleting a
//! file no row names. So two uploads never both take the last room nor evict the same video,
//! and a file is never deleted between an upload of the same bytes placing and linking it.
//! The database side is one `BEGIN IMMEDIATE` transaction per step (`store::videos`).

use std::collections::HashMap;
use std::path::Path;
use std::sync::{Mutex, PoisonError};

use super::videos::{Complete, UploadError, file_path};
use super::{AppState, now_ms};
use crate::error::ServiceError;
use crate::metrics as m;
use crate::store::budget::{self, Refusal};
use crate::store::videos::{self as store, Row};

/// Uploads in flight and the lock that orders file decisions; one per server.
#[derive(Default)]
pub(super) struct VideoLedger {
    turn: tokio::sync::Mutex<()>,
    pending: Mutex<Pending>,
}

#[derive(Default)]
struct Pending {
    teams: HashMap<i64, u64>,
    total: u64,
}

impl VideoLedger {
    fn pending(&self) -> std::sync::MutexGuard<'_, Pending> {
        self.pending.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Room booked for one upload in flight; given back when dropped (the linked row counts
/// from then on).
pub(crate) struct Booking {
    state: AppState,
    team: i64,
    bytes: u64,
}

impl Booking {
    /// The team the booked upload is charged to.
    pub(crate) fn team(&self) -> i64 {
        self.team
    }
}

impl Drop for Booking {
    fn drop(&mut self) {
        let mut p = self.state.inner.videos.pending();
        p.total = p.total.saturating_sub(self.bytes);
        if let Some(t) = p.teams.get_mut(&self.team) {
            *t = t.saturating_sub(self.bytes);
            if *t == 0 {
                p.teams.remove(&self.team);
            }
        }
    }
}

impl AppState {
    /// Book `bytes` for the video of `(run, key)`, evicting the files the budgets need gone
    /// (`store::budget`; their files deleted once no row names them). Refused, with a note on
    /// the episode, when nothing may go.
    pub(crate) async fn book_video(
        &self,
        dir: &Path,
        run: i64,
        key: &str,
        bytes: u64,
    ) -> Result<Booking, UploadError> {
        self.book(dir, run, key, bytes, Media::Video).await
    }

    /// [`Self::book_video`] for the trace of `(run, key)` (its upload is refused without a note:
    /// the episode shows no video then, and says so only where a video was).
    pub(crate) async fn book_trace(
        &self,
        dir: &Path,
        run: i64,
        key: &str,
        bytes: u64,
    ) -> Result<Booking, UploadError> {
        self.book(dir, run, key, bytes, Media::Trace).await
    }

    async fn book(
        &self,
        dir: &Path,
        run: i64,
        key: &str,
        bytes: u64,
        media: Media,
    ) -> Result<Booking, UploadError> {
        let (team, name) = store::team_of_run(self.read_pool(), run)
            .await
            .map_err(ServiceError::from)?
            .ok_or_else(|| ServiceError::not_found(format!("scoring run {run}")))?;
        let cfg = &self.config().video;
        let (team_max, total_max) = (size(cfg.team_max_bytes), size(cfg.total_max_bytes));
        let [team_video, team_trace, total_video, total_trace] = eviction_notes(&name, &team_max, &total_max);
        let _turn = self.inner.videos.turn.lock().await;
        let (team_pending, total_pending) = {
            let p = self.inner.videos.pending();
            (p.teams.get(&team).copied().unwrap_or(0), p.total)
        };
        let ask = budget::Ask {
            team,
            incoming: bytes,
            team_max: cfg.team_max_bytes,
            total_max: cfg.total_max_bytes,
            team_pending,
            total_pending,
            notes: budget::Notes {
                team_video: &team_video,
                team_trace: &team_trace,
                total_video: &total_video,
                total_trace: &total_trace,
            },
        };
        let room = budget::make_room(self.pool(), &ask)
            .await
            .map_err(ServiceError::from)?;
        if let Some(why) = room.refused {
            let what = media.name();
            let why = format!(
                "{what} not stored: {}",
                refusal(why, &name, &team_max, &total_max)
            );
            // A video's episode says why where its video would be; a trace has no such place.
            if media == Media::Video {
                let row = Row {
                    run,
                    key,
                    team,
                    now: now_ms(),
                };
                store::note(self.pool(), row, &why)
                    .await
                    .map_err(ServiceError::from)?;
            }
            metrics::counter!(m::VIDEO_REFUSED, "file" => what).increment(1);
            return Err(UploadError::NoRoom(why));
        }
        for (budget, n) in ["team", "total"].into_iter().zip(room.evicted) {
            metrics::counter!(m::VIDEO_EVICTIONS, "budget" => budget).increment(n as u64);
        }
        self.delete_unlinked_locked(dir, room.orphan_videos).await;
        self.delete_traces_locked(dir, room.orphan_traces).await;
        let mut p = self.inner.videos.pending();
        *p.teams.entry(team).or_default() += bytes;
        p.total += bytes;
        Ok(Booking {
            state: self.clone(),
            team,
            bytes,
        })
    }

    /// Move a finished upload into place and link it to `(run, key)`; the file a replaced link
    /// named is deleted when no row names it any more. Returns the sha256 and size.
    pub(crate) async fn store_video(
        &self,
        dir: &Path,
        booking: Booking,
        run: i64,
        key: &str,
        file: Complete,
    ) -> Result<(String, u64), UploadError> {
        let (sha, bytes) = (file.sha256.clone(), file.bytes);
        let _turn = self.inner.videos.turn.lock().await;
        file.place(dir).await?;
        let row = Row {
            run,
            key,
            team: booking.team,
            now: now_ms(),
        };
        let replaced = store::link(self.pool(), row, &sha, bytes)
            .await
            .map_err(ServiceError::from)?;
        drop(booking);
        self.delete_unlinked_locked(dir, replaced.into_iter().collect())
            .await;
        drop(_turn);
        self.record_stored_video_bytes().await;
        Ok((sha, bytes))
    }

    /// The lock that orders every decision on a file of the video directory (traces too).
    pub(crate) async fn file_turn(&self) -> tokio::sync::MutexGuard<'_, ()> {
        self.inner.videos.turn.lock().await
    }

    /// Link the stored video file `sha` to `(run, key)` (a render of the same trace made it
    /// already). Not booked against the budgets: the row counts from now on, and the next upload
    /// evicts what the budgets need gone. `false` when the file is gone.
    pub(crate) async fn link_stored_video(
        &self,
        dir: &Path,
        run: i64,
        key: &str,
        sha: &str,
    ) -> Result<bool, ServiceError> {
        let Some((team, _)) = store::team_of_run(self.read_pool(), run).await? else {
            return Ok(false);
        };
        let _turn = self.inner.videos.turn.lock().await;
        let Ok(meta) = tokio::fs::metadata(file_path(dir, sha)).await else {
            return Ok(false);
        };
        let row = Row {
            run,
            key,
            team,
            now: now_ms(),
        };
        let replaced = store::link(self.pool(), row, sha, meta.len()).await?;
        self.delete_unlinked_locked(dir, replaced.into_iter().collect())
            .await;
        Ok(true)
    }

    /// Set the stored-bytes gauge from the database (nothing without a recorder).
    pub(crate) async fn record_stored_video_bytes(&self) {
        if !m::installed() {
            return;
        }
        match budget::stored_bytes(self.read_pool()).await {
            Ok(b) => metrics::gauge!(m::VIDEO_STORED_BYTES).set(b as f64),
            Err(e) => tracing::debug!(error = %e, "stored video bytes not recorded"),
        }
    }

    /// Delete the files `shas` that no stored row names (checked again: an upload of the same
    /// bytes may have linked one since). Returns how many were deleted.
    pub(crate) async fn delete_unlinked(&self, dir: &Path, shas: Vec<String>) -> usize {
        let _turn = self.inner.videos.turn.lock().await;
        self.delete_unlinked_locked(dir, shas).await
    }

    /// [`Self::delete_unlinked`], for a caller holding `turn`.
    async fn delete_unlinked_locked(&self, dir: &Path, shas: Vec<String>) -> usize {
        let mut deleted = 0;
        for sha in shas {
            match store::linked(self.pool(), &sha).await {
                Ok(false) => {}
                Ok(true) => continue,
                Err(e) => {
                    tracing::warn!(sha256 = %sha, error = %e, "video file kept: cannot check its links");
                    continue;
                }
            }
            match tokio::fs::remove_file(file_path(dir, &sha)).await {
                Ok(()) => deleted += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => tracing::warn!(sha256 = %sha, error = %e, "cannot delete an unlinked video"),
            }
        }
        deleted
    }
}

/// What a file evicted to make room says where the video was: for the team's budget and the
/// total, of a video (rendered again from its trace) and of a trace (its video lost).
fn eviction_notes(team: &str, team_max: &str, total_max: &str) -> [String; 4] {
    let team_within = format!("team {team}'s videos and traces within [video] team_max_bytes ({team_max})");
    let total_within = format!(
        "all teams' videos and traces within [video] total_max_bytes ({total_max}), from a team over its fair share"
    );
    let again = "it is rendered again from the episode's trace when asked for";
    let lost = "the episode's video can no longer be rendered";
    [
        format!("video removed to keep {team_within}; {again}"),
        format!("trace removed to keep {team_within}; {lost}"),
        format!("video removed to keep {total_within}; {again}"),
        format!("trace removed to keep {total_within}; {lost}"),
    ]
}

/// What an upload books room for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Media {
    Video,
    Trace,
}

impl Media {
    fn name(self) -> &'static str {
        match self {
            Media::Video => "video",
            Media::Trace => "trace",
        }
    }
}

/// Why an upload found no room, in words the episode shows.
fn refusal(why: Refusal, team: &str, team_max: &str, total_max: &str) -> String {
    match why {
        Refusal::InFlight => format!(
            "other uploads in progress fill [video] team_max_bytes ({team_max}) or total_max_bytes ({total_max}); it is tried again"
        ),
        Refusal::TeamProtected => format!(
            "team {team}'s [video] team_max_bytes ({team_max}) is full of traces of ranked test runs, which are kept for verification"
        ),
        Refusal::TotalFair => format!(
            "[video] total_max_bytes ({total_max}) is full and every team is within its fair share (or holds only traces of ranked test runs); it waits until retention or the organiser frees room"
        ),
    }
}

/// Bytes as a config value reads best: `2 GiB`, `512 MiB`, `1.5 GiB`, `3000 bytes`.
fn size(bytes: u64) -> String {
    const UNITS: [(u64, &str); 3] = [(1 << 30, "GiB"), (1 << 20, "MiB"), (1 << 10, "KiB")];
    for (unit, name) in UNITS {
        if bytes >= unit {
            return match bytes % unit {
                0 => format!("{} {name}", bytes / unit),
                _ => format!("{:.1} {name}", bytes as f64 / unit as f64),
            };
        }
    }
    format!("{bytes} bytes")
}

#[cfg(test)]
mod tests {
    #[test]
    fn sizes_read_as_configured() {
        assert_eq!(super::size(2 << 30), "2 GiB");
        assert_eq!(super::size(64 << 20), "64 MiB");
        assert_eq!(super::size(3 << 29), "1.5 GiB");
        assert_eq!(super::size(1000), "1000 bytes");
    }
}
