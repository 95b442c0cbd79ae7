//! Render jobs ("replay on demand", docs/contest/video.md): the server keeps an online episode's
//! trace instead of its video, and when the video is first asked for it hands a worker a render job
//! (`Job.render`) at the lowest priority. The worker replays the trace into the episode video
//! (the recorder `eval --record` uses, as a hook on the replay), heartbeats the render's
//! progress, and uploads the MP4 through `UploadVideo`, which completes the render. The trace
//! is fetched first, in chunks (`super::fetch`): a lease reply never carries it.
//!
//! Rendering never delays evaluation: the server hands a render out only while no evaluation
//! job is queued, the worker takes at most one render per slot and keeps leasing episodes
//! beside them, and a render's thread holds its core at background priority, giving it to any
//! waiting episode between two steps.
//!
//! Policy: a video is made only of the episode that was scored. The replay must reproduce the
//! trace bit for bit (`kitchen_r_episode::trace::replay_with`) and its outcome must agree with
//! the result the server stored (`RenderJob.expected`); otherwise nothing is uploaded and the
//! render is reported failed (`FailRender`) with the reason. A render lease the server cancels,
//! or a worker that drains, stops the replay; the server requeues the render when the lease
//! expires.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};
use std::time::Duration;

use kitchen_r_episode::runner::{StepHook, TaskRecord};
use kitchen_r_episode::trace::{ReplayError, Trace, replay_with};
use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_record::video::episode::{EpisodeVideo, RecordedVideo, VideoHook};
use kitchen_r_sim::{Action, Sim, StepInfo};
use tokio::sync::{oneshot, watch};
use tonic::Request;
use tracing::{Instrument, info, info_span, warn};

use super::JobContext;
use super::cores::{Core, Cores};
use super::fetch::FetchError;
use super::worker::Worker;

/// The share of a render spent replaying; the rest is the encoder's flush and the upload.
const REPLAY_SHARE: f32 = 0.95;

/// Why a render made no video; the text is what the episode shows.
pub(crate) const DISAGREES: &str = "replay disagrees with the stored result";

/// A render in progress, shared by its thread and the task that heartbeats it.
#[derive(Debug, Default)]
pub(crate) struct RenderControl {
    cancelled: AtomicBool,
    /// `f32` bits of the share done.
    progress: AtomicU32,
}

impl RenderControl {
    pub(crate) fn progress(&self) -> f32 {
        f32::from_bits(self.progress.load(Ordering::Relaxed))
    }
    fn set_progress(&self, p: f32) {
        self.progress
            .store(p.clamp(0.0, 1.0).to_bits(), Ordering::Relaxed);
    }
    fn cancel(&self) {
        self.cancelled.store(true, Ordering::SeqCst);
    }
}

/// Render jobs in flight in one worker (the lease loop asks for one more only below its slots).
#[derive(Debug, Default, Clone)]
pub(crate) struct InFlight(Arc<AtomicUsize>);

impl InFlight {
    pub(crate) fn in_flight(&self) -> usize {
        self.0.load(Ordering::SeqCst)
    }

    /// Count one render until the returned guard is dropped.
    pub(crate) fn start(&self) -> InFlightGuard {
        self.0.fetch_add(1, Ordering::SeqCst);
        InFlightGuard(self.0.clone())
    }
}

/// One render counted in [`InFlight`].
pub(crate) struct InFlightGuard(Arc<AtomicUsize>);

impl Drop for InFlightGuard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Counts the replay's progress in sim time, stops it when cancelled, and lets every episode
/// waiting for a core go first between two steps (rendering is background work).
struct Progress<'a> {
    control: &'a RenderControl,
    total_sim_s: f64,
    core: &'a mut Core,
}

impl StepHook for Progress<'_> {
    fn on_step(&mut self, _: &Sim, _: &Action, info: &StepInfo) -> Result<(), String> {
        if self.control.cancelled.load(Ordering::SeqCst) {
            return Err("render cancelled".into());
        }
        self.core.yield_to_episodes();
        let share = (info.time / self.total_sim_s.max(1e-9)) as f32;
        self.control.set_progress(share.min(1.0) * REPLAY_SHARE);
        Ok(())
    }
}

/// Replay `job`'s trace into its video, checked against the trace and the stored result.
/// Blocking: run it on a thread of its own.
pub(crate) fn render(
    job: &pb::RenderJob,
    trace_gz: &[u8],
    ctx: &JobContext,
    control: &RenderControl,
    core: &mut Core,
) -> Result<RecordedVideo, String> {
    let trace = Trace::from_bytes(trace_gz).map_err(|e| format!("the trace does not load: {e}"))?;
    let plan = &trace.episode.plan;
    let n_tasks = trace.run.max_tasks.map_or(plan.len(), |m| m.min(plan.len()));
    let video = EpisodeVideo::new(plan, n_tasks, job.video_max_bytes as usize);
    core.hold_background();
    let mut progress = Progress {
        control,
        total_sim_s: trace.outcome.sim_time,
        core,
    };
    let mut recorder = VideoHook::new(&mut progress, video);
    let out =
        replay_with(&trace, &ctx.assets, &ctx.sim, &ctx.sensors, &mut recorder).map_err(|e| match e {
            ReplayError::Disagrees { what } => format!("{DISAGREES}: {what}"),
            e if control.cancelled.load(Ordering::SeqCst) => format!("render cancelled ({e})"),
            e => format!("the replay failed: {e}"),
        })?;
    agrees_with_stored(&out.tasks, &job.expected).map_err(|what| format!("{DISAGREES}: {what}"))?;
    let video = recorder.into_video();
    // The encoder's flush is one block of work: it waits, too, until no episode waits.
    core.yield_to_episodes();
    video.finish()
}

/// The replay's outcome against the result the server stored: the same tasks, the same
/// successes, the same completion times (the stored result went through JSON; its times are
/// compared to a nanosecond).
pub(crate) fn agrees_with_stored(replayed: &[TaskRecord], stored: &[pb::TaskResult]) -> Result<(), String> {
    if replayed.len() != stored.len() {
        return Err(format!(
            "{} task(s) replayed, {} stored",
            replayed.len(),
            stored.len()
        ));
    }
    for (r, s) in replayed.iter().zip(stored) {
        if r.index != s.index as usize || r.success != s.success {
            return Err(format!(
                "task {}: replayed {}, stored {}",
                r.index,
                verdict(r.success),
                verdict(s.success)
            ));
        }
        let time = if r.success { r.sim_time } else { 0.0 };
        if (time - s.completion_time_s).abs() > 1e-9 {
            return Err(format!(
                "task {}: completed at {time} s replayed, {} s stored",
                r.index, s.completion_time_s
            ));
        }
    }
    Ok(())
}

fn verdict(success: bool) -> &'static str {
    if success { "success" } else { "failure" }
}

impl Worker {
    /// Run one render job: replay with heartbeats carrying its progress, then upload the video
    /// or report why there is none.
    pub(super) async fn render_job(&self, job: pb::Job, stop: &mut watch::Receiver<bool>) {
        let span = info_span!("render", render_id = job.job_id, run = job.run_id, episode = %job.episode_key, attempt = job.attempt);
        async {
            info!("render started");
            let control = Arc::new(RenderControl::default());
            let open = || {
                let mut client = self.client.clone();
                let req = Request::new(pb::FetchTraceRequest {
                    worker_id: self.id.clone(),
                    render_id: job.job_id,
                    attempt: job.attempt,
                });
                async move { client.fetch_trace(req).await.map(tonic::Response::into_inner) }
            };
            let fetch = super::fetch::trace(job.render.as_ref(), open);
            let trace_gz = match self.heartbeating(&job, &control, fetch, stop).await {
                None => return,
                Some(Ok(t)) => t,
                Some(Err(FetchError::LeaseGone)) => {
                    info!("render lease gone while fetching its trace: stopping");
                    return;
                }
                // The lease expires and the server queues the render again.
                Some(Err(FetchError::Transient(e))) => {
                    warn!("the trace could not be fetched ({e}); the render will be tried again");
                    return;
                }
                Some(Err(FetchError::Fails(why))) => {
                    warn!(%why, "render failed");
                    self.fail_render(&job, &why).await;
                    return;
                }
            };
            info!(trace_bytes = trace_gz.len(), "trace fetched");
            let done = spawn_render(&job, trace_gz, self.ctx.clone(), control.clone(), self.cores.clone());
            let replayed = async { done.await.unwrap_or_else(|_| Err("the render thread panicked".into())) };
            let Some(result) = self.heartbeating(&job, &control, replayed, stop).await else {
                return;
            };
            let why = match result {
                Ok(video) => {
                    info!(
                        frames = video.frames,
                        bytes = video.mp4.len(),
                        encode_s = video.encode_time.as_secs_f64(),
                        "rendered"
                    );
                    match super::upload::upload_video(&self.client, &self.id, &job, video.mp4).await {
                        Ok(()) => return,
                        // The server may take it later (storage budgets full: the server queues
                        // the render again with the reason; a restart): nothing to report.
                        Err(s) if super::rpc::retryable(&s) => {
                            warn!("the rendered video was not stored ({:?}: {}); the render will be tried again", s.code(), s.message());
                            return;
                        }
                        Err(s) => format!("the server did not store the video: {}", s.message()),
                    }
                }
                Err(why) => why,
            };
            warn!(%why, "render failed");
            self.fail_render(&job, &why).await;
        }
        .instrument(span)
        .await;
    }

    /// Run `work` while heartbeating the render lease with `control`'s progress; `None` (and
    /// `control` cancelled) when the server cancels the lease or the worker drains.
    async fn heartbeating<T>(
        &self,
        job: &pb::Job,
        control: &RenderControl,
        work: impl std::future::Future<Output = T>,
        stop: &mut watch::Receiver<bool>,
    ) -> Option<T> {
        let mut next = super::rpc::heartbeat_in(job.lease_expires_at_ms);
        tokio::pin!(work);
        loop {
            tokio::select! {
                r = &mut work => return Some(r),
                () = tokio::time::sleep(next) => {
                    match self.render_heartbeat(job, control.progress()).await {
                        Some(d) => next = d,
                        None => {
                            control.cancel();
                            info!("render lease cancelled by the server: stopping");
                            return None;
                        }
                    }
                }
                _ = stop.changed() => {
                    // Cheap to redo: the lease expires and the server queues the render again.
                    control.cancel();
                    info!("draining: render stopped");
                    return None;
                }
            }
        }
    }

    /// One render heartbeat; when the next is due, or `None` when the lease is gone.
    async fn render_heartbeat(&self, job: &pb::Job, progress: f32) -> Option<Duration> {
        let mut req = Request::new(pb::HeartbeatRequest {
            worker_id: self.id.clone(),
            job_id: job.job_id,
            attempt: job.attempt,
            render: true,
            progress,
            ..Default::default()
        });
        req.set_timeout(Duration::from_secs(10));
        match self.client.clone().heartbeat(req).await {
            Ok(r) if r.get_ref().cancelled => None,
            Ok(r) => Some(super::rpc::heartbeat_in(r.into_inner().lease_expires_at_ms)),
            Err(s) => {
                warn!(
                    "render heartbeat failed ({:?}: {}); retrying",
                    s.code(),
                    s.message()
                );
                Some(Duration::from_secs(1))
            }
        }
    }

    /// Tell the server why the render made no video (once; a lost answer leaves the lease to
    /// expire, and the render is tried again).
    async fn fail_render(&self, job: &pb::Job, why: &str) {
        let mut req = Request::new(pb::FailRenderRequest {
            worker_id: self.id.clone(),
            render_id: job.job_id,
            attempt: job.attempt,
            error: why.to_string(),
        });
        req.set_timeout(Duration::from_secs(10));
        if let Err(s) = self.client.clone().fail_render(req).await {
            warn!(
                "reporting the failed render failed ({:?}: {})",
                s.code(),
                s.message()
            );
        }
    }
}

/// Render on a thread of its own, holding a simulation core while it replays, at a lower
/// priority than any episode ([`Core::hold_background`]).
fn spawn_render(
    job: &pb::Job,
    trace_gz: Vec<u8>,
    ctx: Arc<JobContext>,
    control: Arc<RenderControl>,
    cores: Cores,
) -> oneshot::Receiver<Result<RecordedVideo, String>> {
    let (tx, rx) = oneshot::channel();
    let job_spec = job.render.clone().unwrap_or_default();
    let spawned = std::thread::Builder::new()
        .name(format!("render-{}", job.job_id))
        .spawn(move || {
            let mut core = cores.core();
            let _ = tx.send(render(&job_spec, &trace_gz, &ctx, &control, &mut core));
        });
    if let Err(e) = spawned {
        warn!("cannot start a render thread: {e}");
    }
    rx
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(successes: &[(bool, f64)]) -> Vec<TaskRecord> {
        (successes.iter().enumerate())
            .map(|(index, &(success, sim_time))| TaskRecord {
                index,
                step: "pick the bowl".into(),
                success,
                sim_time,
                failure: None,
                aborts_episode: false,
                policy_calls: 1,
                corrections: Default::default(),
            })
            .collect()
    }

    fn stored(success: bool, completion_time_s: f64) -> pb::TaskResult {
        pb::TaskResult {
            success,
            completion_time_s,
            ..Default::default()
        }
    }

    #[test]
    fn a_replay_must_agree_with_the_stored_result() {
        let out = outcome(&[(true, 4.5)]);
        assert!(agrees_with_stored(&out, &[stored(true, 4.5)]).is_ok());
        let err = agrees_with_stored(&out, &[stored(false, 0.0)]).unwrap_err();
        assert!(err.contains("replayed success, stored failure"), "{err}");
        assert!(agrees_with_stored(&out, &[stored(true, 4.6)]).is_err());
        assert!(agrees_with_stored(&out, &[]).is_err());
        // A failed task's stored completion time is 0 whatever its sim time.
        assert!(agrees_with_stored(&outcome(&[(false, 3.0)]), &[stored(false, 0.0)]).is_ok());
    }
}
