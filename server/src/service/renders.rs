//! Videos rendered on demand (docs/contest/video.md): an online episode's trace is stored instead
//! of its video, and the video is rendered from it by a simulation worker when first asked for (the
//! server never steps physics).
//!
//! Policy:
//! - asking for an episode's video (its URL, or a page showing the episode) with no video
//!   stored but a trace queues a render (`video_renders`) and answers "rendering"; a render of
//!   the same trace that finished before lends its video at once (the trace is the cache key);
//! - renders go to workers through `Lease` at the lowest priority: only while no evaluation job
//!   is queued (checked in the claim itself), one per call, so evaluation is never delayed;
//! - a render lease is heartbeated with its progress; one that expires (a killed worker) is
//!   queued again like an episode job, and fails after `control.max_attempts` leases;
//! - the worker checks the replay against the trace and the stored result the render job
//!   carries; on disagreement it reports the render failed and no video is stored. A failed
//!   render of a trace is not tried again (the same replay would disagree again): the episode
//!   shows why. A new trace of the episode queues a new render.

use std::collections::HashMap;
use std::path::Path;

use super::lease::HeartbeatOutcome;
pub(crate) use super::progress::VideoView;
use super::videos::{Complete, StoredVideo, UploadError, trace_path};
use super::{AppState, Caller, WorkerCred, now_ms};
use crate::config::Prerender;
use crate::episodes::TaskOutcome;
use crate::error::ServiceError;
use crate::store::{self, renders as store_renders};

/// Longest failure text kept for a render.
const MAX_ERROR_CHARS: usize = 2000;
/// How long a render whose video found no room waits before it is leased again (doubling with
/// each wait, up to an hour).
const RENDER_WAIT_MS: i64 = 60_000;

/// What an episode's video is now.
#[derive(Debug, Clone)]
pub(crate) enum VideoState {
    Ready(StoredVideo),
    /// Queued (`leased` false) or being rendered, with the share done.
    Rendering {
        leased: bool,
        progress: f64,
    },
    Failed(String),
}

/// A render job as handed to a worker.
#[derive(Debug, Clone)]
pub(crate) struct LeasedRender {
    pub id: i64,
    pub attempt: u32,
    pub lease_expires_at_ms: i64,
    pub run_id: i64,
    pub episode_key: String,
    /// The trace the worker fetches (`AppState::render_trace`): its sha256 and size.
    pub trace_sha256: String,
    pub trace_bytes: u64,
    pub expected: Vec<TaskOutcome>,
}

/// The trace of a held render lease, to stream to its worker.
#[derive(Debug, Clone)]
pub(crate) struct RenderTrace {
    pub path: std::path::PathBuf,
    pub bytes: u64,
    pub run_id: i64,
    pub episode_key: String,
}

impl AppState {
    /// The video of one episode a caller may see, or the state of its render, queued now when
    /// there is a trace and no video. Not found when the episode has neither (or is not the
    /// caller's to see).
    pub(crate) async fn video_or_render(
        &self,
        caller: &Caller,
        id: i64,
        key: &str,
    ) -> Result<VideoState, ServiceError> {
        let not_found = || ServiceError::not_found(format!("a video of episode {key:?} of submission {id}"));
        let (dir, run) = self.media_run(caller, id).await?.ok_or_else(not_found)?;
        self.ask_video(&dir, run, key).await?.ok_or_else(not_found)
    }

    /// The video of `(run, key)` or its render's state, queuing the render when needed; `None`
    /// when there is neither a video nor a trace.
    pub(crate) async fn ask_video(
        &self,
        dir: &Path,
        run: i64,
        key: &str,
    ) -> Result<Option<VideoState>, ServiceError> {
        self.queue_render(dir, run, key, false).await
    }

    /// A worker's finished trace upload: stored as `(run, key)`'s trace, then its video queued
    /// for pre-rendering as `[video] prerender` says. Returns the trace's sha256 and size.
    pub(crate) async fn trace_uploaded(
        &self,
        dir: &Path,
        booking: super::video_budget::Booking,
        run: i64,
        key: &str,
        file: Complete,
    ) -> Result<(String, u64), UploadError> {
        let stored = self.store_trace(dir, booking, run, key, file).await?;
        // Best effort: the trace is stored whatever happens to its pre-render.
        if let Err(e) = self.prerender(dir, run, key).await {
            tracing::warn!(run, episode = %key, error = %e, "cannot queue the video's pre-render");
        }
        Ok(stored)
    }

    /// A trace of `(run, key)` was just stored: with `[video] prerender`, queue its video's
    /// render behind every asked-for one (`failed`: only when the stored result failed a task).
    pub(crate) async fn prerender(&self, dir: &Path, run: i64, key: &str) -> Result<(), ServiceError> {
        match self.config().video.prerender {
            Prerender::None => return Ok(()),
            Prerender::All => {}
            Prerender::Failed => {
                let tasks = store_renders::stored_tasks(self.read_pool(), run, key).await?;
                if tasks.is_none_or(|t| t.iter().all(|t| t.success)) {
                    return Ok(());
                }
            }
        }
        if store_renders::render(self.read_pool(), run, key).await?.is_some() {
            return Ok(());
        }
        self.queue_render(dir, run, key, true).await?;
        Ok(())
    }

    /// [`Self::ask_video`], or a pre-render's queuing (`prerender`: behind asked-for renders).
    async fn queue_render(
        &self,
        dir: &Path,
        run: i64,
        key: &str,
        prerender: bool,
    ) -> Result<Option<VideoState>, ServiceError> {
        if let Some(v) = self.stored_video(dir, run, key).await? {
            return Ok(Some(VideoState::Ready(v)));
        }
        let Some(trace) = store::traces::trace(self.read_pool(), run, key).await? else {
            return Ok(None);
        };
        if let Some(r) = store_renders::render(self.read_pool(), run, key).await?
            && r.trace_sha256 == trace
        {
            match r.state.as_str() {
                "queued" | "leased" => {
                    if !prerender && r.state == "queued" {
                        store_renders::promote(self.pool(), run, key).await?;
                    }
                    return Ok(Some(VideoState::Rendering {
                        leased: r.state == "leased",
                        progress: r.progress,
                    }));
                }
                "failed" => return Ok(Some(VideoState::Failed(r.error.unwrap_or_default()))),
                // Done, but its video is gone since (retention, a budget): render again.
                _ => {}
            }
        }
        let now = now_ms();
        store_renders::request(self.pool(), run, key, &trace, now, prerender).await?;
        // The same trace rendered before: its video is this episode's too.
        if let Some(video) = store_renders::rendered(self.read_pool(), &trace).await?
            && self.link_stored_video(dir, run, key, &video).await?
        {
            store_renders::reused(self.pool(), run, key, &video, now).await?;
            rendered_metric("reused", 1);
            tracing::info!(run, episode = %key, sha256 = %video, "video of the same trace reused");
            return Ok(self.stored_video(dir, run, key).await?.map(VideoState::Ready));
        }
        rendered_metric(if prerender { "prerender_queued" } else { "queued" }, 1);
        tracing::info!(run, episode = %key, prerender, "video render queued");
        self.wake_leases();
        Ok(Some(VideoState::Rendering {
            leased: false,
            progress: 0.0,
        }))
    }

    /// A page shows `view` (submission `id`) to `caller`: queue the renders of the episodes it
    /// shows with a trace and no video. `true` when one was queued (the view is out of date).
    pub(crate) async fn render_shown(
        &self,
        caller: &Caller,
        id: i64,
        view: &super::SubmissionView,
    ) -> Result<bool, ServiceError> {
        let evaluation = view.latest_run.as_ref().and_then(|r| r.evaluation.as_ref());
        let available: Vec<&str> = (evaluation.iter())
            .flat_map(|e| &e.episodes)
            .filter(|ep| ep.video.as_ref().is_some_and(|v| v.status == "available"))
            .map(|ep| ep.key.as_str())
            .collect();
        if available.is_empty() {
            return Ok(false);
        }
        let Some((dir, run)) = self.media_run(caller, id).await? else {
            return Ok(false);
        };
        // A video removed to keep a budget is rendered again only when asked for by its URL: a
        // page whose run outgrew its budget would otherwise evict and render in a circle.
        let notes = self.video_keys(run).await?;
        let mut queued = false;
        for key in available {
            if !matches!(notes.get(key), Some(Some(_))) {
                self.ask_video(&dir, run, key).await?;
                queued = true;
            }
        }
        Ok(queued)
    }

    /// Each episode of `run`'s video as the API shows it: every episode with a trace, a video or
    /// a render. Reads only: nothing is queued.
    pub(crate) async fn video_views(
        &self,
        run: i64,
        url: impl Fn(&str) -> String,
    ) -> Result<HashMap<String, VideoView>, ServiceError> {
        let mut out = HashMap::new();
        if self.video_dir().is_none() {
            return Ok(out);
        }
        let view = |status: &str, progress: f64, key: &str| VideoView {
            status: status.into(),
            progress,
            url: Some(url(key)),
            error: None,
            waiting: None,
        };
        for key in store::traces::keys(self.read_pool(), run).await? {
            out.insert(key.clone(), view("available", 0.0, &key));
        }
        for r in store_renders::of_run(self.read_pool(), run).await? {
            let v = match r.state.as_str() {
                "queued" => VideoView {
                    waiting: r.waiting.clone(),
                    ..view("queued", 0.0, &r.episode_key)
                },
                "leased" => view("rendering", r.progress, &r.episode_key),
                "failed" => VideoView {
                    error: r.error.clone(),
                    ..view("failed", 0.0, &r.episode_key)
                },
                _ => continue,
            };
            out.insert(r.episode_key.clone(), v);
        }
        for (key, note) in self.video_keys(run).await? {
            if note.is_none() {
                out.insert(key.clone(), view("ready", 1.0, &key));
            }
        }
        Ok(out)
    }

    /// Lease the oldest queued render to `worker`, unless an evaluation job waits.
    pub(crate) async fn claim_render(&self, worker: &str) -> Result<Option<LeasedRender>, ServiceError> {
        let Some(dir) = self.video_dir() else {
            return Ok(None);
        };
        let now = now_ms();
        if !store_renders::any_queued(self.read_pool(), now).await? {
            return Ok(None);
        }
        let until = now + self.lease_ms();
        let Some(c) = store_renders::claim(self.pool(), worker, now, until).await? else {
            return Ok(None);
        };
        let lease = store_renders::Lease {
            id: c.id,
            attempt: c.attempt,
            owner: worker,
        };
        let expected = store_renders::stored_tasks(self.read_pool(), c.run_id, &c.episode_key).await?;
        // Only the size here: the worker fetches the bytes in chunks (`render_trace`), so a
        // trace of any size the server accepted reaches it (a lease reply is one message).
        let trace = tokio::fs::metadata(trace_path(&dir, &c.trace_sha256)).await;
        let max = self.config().video.max_bytes;
        let (expected, trace_bytes) = match (expected, trace) {
            (None, _) => {
                return self
                    .refuse_render(lease, "the episode has no stored result")
                    .await;
            }
            (_, Err(e)) if e.kind() == std::io::ErrorKind::NotFound => {
                return self
                    .refuse_render(
                        lease,
                        "the trace is gone (removed to keep a storage budget, or past retention)",
                    )
                    .await;
            }
            (_, Err(e)) => {
                return self
                    .refuse_render(lease, &format!("the trace file cannot be read: {e}"))
                    .await;
            }
            (Some(_), Ok(m)) if m.len() > max => {
                let why = format!(
                    "the trace is too large to render: {} bytes, more than [video] max_bytes ({max}); raise it to render this video",
                    m.len()
                );
                return self.refuse_render(lease, &why).await;
            }
            (Some(e), Ok(m)) => (e, m.len()),
        };
        tracing::info!(render = c.id, run = c.run_id, episode = %c.episode_key, attempt = c.attempt, worker, trace_bytes, "render leased");
        Ok(Some(LeasedRender {
            id: c.id,
            attempt: u32::try_from(c.attempt).unwrap_or(u32::MAX),
            lease_expires_at_ms: c.lease_expires_at,
            run_id: c.run_id,
            episode_key: c.episode_key,
            trace_sha256: c.trace_sha256,
            trace_bytes,
            expected,
        }))
    }

    /// The trace of the render lease `(id, attempt)` that `worker` holds, to stream to it.
    pub(crate) async fn render_trace(
        &self,
        _: WorkerCred,
        worker: &str,
        id: i64,
        attempt: u32,
    ) -> Result<RenderTrace, ServiceError> {
        let Some(dir) = self.video_dir() else {
            return Err(ServiceError::Conflict(
                "this server does not store episode traces (`[video] enabled` is false)".into(),
            ));
        };
        let lease = store_renders::Lease {
            id,
            attempt: i64::from(attempt),
            owner: worker,
        };
        let Some(c) = store_renders::leased(self.read_pool(), lease).await? else {
            return Err(ServiceError::Conflict(format!(
                "render {id} attempt {attempt} is not leased to worker {worker:?}"
            )));
        };
        let path = trace_path(&dir, &c.trace_sha256);
        match tokio::fs::metadata(&path).await {
            Ok(m) => Ok(RenderTrace {
                path,
                bytes: m.len(),
                run_id: c.run_id,
                episode_key: c.episode_key,
            }),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(ServiceError::not_found(format!(
                "the trace of render {id} (removed to keep a storage budget, or past retention)"
            ))),
            Err(e) => Err(ServiceError::Internal(
                anyhow::Error::new(e).context("reading a trace file"),
            )),
        }
    }

    /// The video of render lease `(id, attempt)` found no room in the storage budgets: the
    /// render waits, queued, with `why` shown where its video would be (tried again after a
    /// minute, then less often, up to hourly; waiting is not an attempt).
    pub(crate) async fn render_waits(&self, id: i64, attempt: i64, why: &str) -> Result<(), ServiceError> {
        let why: String = why.chars().take(MAX_ERROR_CHARS).collect();
        if store_renders::wait(self.pool(), id, attempt, &why, now_ms(), RENDER_WAIT_MS).await? {
            rendered_metric("waiting", 1);
            tracing::info!(render = id, attempt, %why, "render waits for room");
        }
        Ok(())
    }

    /// A rendered video was stored: its render is done.
    pub(crate) async fn render_done(&self, id: i64, attempt: i64, video: &str) -> Result<(), ServiceError> {
        store_renders::done(self.pool(), id, attempt, video, now_ms()).await?;
        rendered_metric("done", 1);
        Ok(())
    }

    async fn refuse_render(
        &self,
        lease: store_renders::Lease<'_>,
        why: &str,
    ) -> Result<Option<LeasedRender>, ServiceError> {
        tracing::warn!(render = lease.id, %why, "render not handed out");
        store_renders::fail(self.pool(), lease, why, now_ms()).await?;
        rendered_metric("failed", 1);
        Ok(None)
    }

    /// Extend a render lease and record its progress.
    pub(crate) async fn render_heartbeat(
        &self,
        _: WorkerCred,
        worker: &str,
        id: i64,
        attempt: u32,
        progress: f32,
    ) -> Result<HeartbeatOutcome, ServiceError> {
        let now = now_ms();
        let lease = store_renders::Lease {
            id,
            attempt: i64::from(attempt),
            owner: worker,
        };
        let p = if progress.is_finite() {
            f64::from(progress)
        } else {
            0.0
        };
        let until = store_renders::heartbeat(self.pool(), lease, now + self.lease_ms(), p, now).await?;
        Ok(HeartbeatOutcome {
            lease_expires_at_ms: until,
        })
    }

    /// A worker could not render: the episode shows `error` where its video would be.
    pub(crate) async fn fail_render(
        &self,
        _: WorkerCred,
        worker: &str,
        id: i64,
        attempt: u32,
        error: &str,
    ) -> Result<bool, ServiceError> {
        let error = match error.trim() {
            "" => "the worker made no video and said nothing why".to_string(),
            e => e.chars().take(MAX_ERROR_CHARS).collect(),
        };
        let lease = store_renders::Lease {
            id,
            attempt: i64::from(attempt),
            owner: worker,
        };
        let failed = store_renders::fail(self.pool(), lease, &error, now_ms()).await?;
        rendered_metric("failed", u64::from(failed));
        tracing::warn!(render = id, attempt, worker, failed, %error, "render failed");
        Ok(failed)
    }

    /// Queue again the renders whose lease expired; returns how many.
    pub(crate) async fn reap_renders(&self, now: i64) -> Result<u64, ServiceError> {
        let max = i64::from(self.config().control.max_attempts);
        let n = store_renders::reap(self.pool(), now, max).await?;
        if n > 0 {
            rendered_metric("requeued", n);
            tracing::info!(requeued = n, "expired render leases queued again");
            self.wake_leases();
        }
        Ok(n)
    }
}

/// Count renders by outcome (`crate::metrics::VIDEO_RENDERS`).
fn rendered_metric(outcome: &'static str, n: u64) {
    metrics::counter!(crate::metrics::VIDEO_RENDERS, "outcome" => outcome).increment(n);
}
