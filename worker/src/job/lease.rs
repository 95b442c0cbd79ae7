//! The worker loop: one lease loop taking jobs from the server's `kitchen_r.worker.v1.Worker`
//! service while there is room, and one task per leased job that runs its episode on a thread of
//! its own (episodes are CPU-bound and the policy client blocks), heartbeats every third of the
//! lease while it runs, and reports the result.
//!
//! Episodes and cores are counted apart: `slots` core permits ([`Cores`]) are shared by up to
//! `max_episodes` episodes in flight, and an episode holds a permit only while it simulates. The
//! loop takes one job per free core at once, and more only while the cores were idle (the
//! episodes are waiting on slow policies; see [`Pacer`]). The server never leases a run more
//! episodes at once than its policy's `max_concurrency`.
//!
//! Failure policy: the server being down or restarting is transient, so every call is retried
//! with capped exponential backoff and the worker never exits for it; only a refused worker
//! token stops the loop (retrying cannot fix it). Results are idempotent server-side, so a report
//! whose answer was lost is simply sent again.
//!
//! Draining: on shutdown the worker stops leasing at once, running episodes go on (heartbeated) for
//! up to `drain_grace_s` and are reported as usual when they finish in time; an episode still
//! running then is stopped at its next control step and *released* (`Release`): the server queues
//! it again at once, for another worker, without using an attempt, and nothing of it is recorded.
//! Only when the release cannot get through either does the lease expire and the server's reaper
//! requeue the job.

use std::future::Future;
use std::sync::Arc;
use std::time::{Duration, Instant};

use kitchen_r_proto::worker::v1 as pb;
use tokio::sync::{oneshot, watch};
use tokio::task::JoinSet;
use tonic::{Code, Request};
use tracing::{Instrument, error, info, info_span, warn};

use super::cores::Cores;
use super::execute::{Executed, JobControl, execute_job_traced};
use super::rpc::{heartbeat_in, retryable};
use super::worker::Worker;
use super::{JobContext, WorkerConfig, WorkerError};

/// How long a shutting-down worker keeps trying to hand in its last result.
const SHUTDOWN_GRACE: Duration = Duration::from_secs(5);
/// How long a draining worker waits for the answer of a Lease call in flight (jobs the server
/// claimed for it are released, not left to expire).
const LEASE_SETTLE: Duration = Duration::from_secs(1);
/// How often the worker looks at how busy its cores were, and the shortest window it judges by.
const PACE_WINDOW: Duration = Duration::from_millis(250);
/// Above this share of busy core time, one more episode would only wait for a core.
const BUSY: f64 = 0.9;
/// Jobs asked for in one Lease call (the server's own cap is 64).
const MAX_JOBS_PER_CALL: usize = 16;
/// Longest pause between retries of a failed call.
const MAX_BACKOFF: Duration = Duration::from_secs(30);

/// Build and run until `shutdown` resolves.
pub async fn run_worker(cfg: WorkerConfig, shutdown: impl Future<Output = ()>) -> Result<(), WorkerError> {
    Worker::build(cfg).await?.run(shutdown).await
}

impl Worker {
    /// The lease owner name this worker uses.
    pub fn id(&self) -> &str {
        &self.id
    }

    /// Lease and run episodes until `shutdown` resolves (then drain) or the server refuses the
    /// worker token.
    pub async fn run(self, shutdown: impl Future<Output = ()>) -> Result<(), WorkerError> {
        let (stop_tx, stop_rx) = watch::channel(false);
        let me = Arc::new(self);
        let mut jobs = JoinSet::new();
        info!(
            worker = %me.id,
            slots = me.cores.total(),
            max_episodes = me.cfg.episode_limit(),
            server = %me.cfg.server,
            "worker running"
        );
        tokio::pin!(shutdown);
        let result = {
            let leasing = me.clone().lease_loop(stop_rx, &mut jobs);
            tokio::pin!(leasing);
            tokio::select! {
            () = &mut shutdown => {
                info!(
                    grace_s = me.cfg.drain_grace_s,
                    "draining: no more leases; running episodes get the grace period, then are released"
                );
                let _ = stop_tx.send(true);
                (&mut leasing).await
            }
            r = &mut leasing => {
                let _ = stop_tx.send(true);
                r
            }
            }
        };
        while let Some(r) = jobs.join_next().await {
            if let Err(e) = r {
                error!("an episode task failed: {e}");
            }
        }
        result
    }

    /// Lease while there is room (see [`Pacer`]) and start each job as a task of `jobs`; returns
    /// when `stop` turns true (jobs leased meanwhile are released) or the token is refused.
    async fn lease_loop(
        self: Arc<Self>,
        mut stop: watch::Receiver<bool>,
        jobs: &mut JoinSet<()>,
    ) -> Result<(), WorkerError> {
        let mut backoff = Backoff::default();
        let mut pacer = Pacer::new(self.cores.clone(), self.cfg.episode_limit());
        let renders = super::render::InFlight::default();
        let wait = self.cfg.lease_wait();
        loop {
            while jobs.try_join_next().is_some() {}
            if *stop.borrow() {
                return Ok(());
            }
            // Renders run beside episodes (at background priority): only episodes are paced.
            let rendering = renders.in_flight();
            let room = pacer.room(jobs.len().saturating_sub(rendering));
            if room == 0 {
                // Full, or the cores were busy: look again when an episode ends or a window passes.
                tokio::select! {
                    _ = jobs.join_next(), if !jobs.is_empty() => {}
                    () = tokio::time::sleep(PACE_WINDOW) => {}
                    _ = stop.changed() => {}
                }
                continue;
            }
            let mut req = Request::new(pb::LeaseRequest {
                worker_id: self.id.clone(),
                max_jobs: room.min(MAX_JOBS_PER_CALL) as u32,
                wait_ms: self.cfg.lease_wait_ms,
                // At most one render per slot in flight.
                max_renders: self.cores.total().saturating_sub(rendering).min(1) as u32,
            });
            req.set_timeout(wait + Duration::from_secs(10));
            let asked = Instant::now();
            let mut client = self.client.clone();
            let call = client.lease(req);
            tokio::pin!(call);
            let answer = tokio::select! {
                r = &mut call => r,
                _ = stop.changed() => {
                    // The server may have claimed jobs for this call already: give its answer a
                    // moment, so they are released rather than left leased until they expire.
                    if let Ok(Ok(r)) = tokio::time::timeout(LEASE_SETTLE, call).await {
                        for job in r.into_inner().jobs {
                            self.release(&job, "worker draining: leased as it stopped").await;
                        }
                    }
                    return Ok(());
                }
            };
            match answer {
                Ok(r) => {
                    backoff.reset();
                    let leased = r.into_inner().jobs;
                    if leased.is_empty() && asked.elapsed() < Duration::from_millis(100) {
                        // A server that does not hold the call open must not be hammered.
                        pause(Duration::from_millis(500), &mut stop).await;
                    }
                    pacer.leased();
                    for job in leased {
                        if *stop.borrow() {
                            // Draining: a job not started yet goes back at once.
                            self.release(&job, "worker draining: not started").await;
                            continue;
                        }
                        let (w, mut stop) = (self.clone(), stop.clone());
                        match job.render.is_some() {
                            true => {
                                let counted = renders.start();
                                jobs.spawn(async move {
                                    w.render_job(job, &mut stop).await;
                                    drop(counted);
                                })
                            }
                            false => jobs.spawn(async move { w.job(job, &mut stop).await }),
                        };
                    }
                }
                Err(s) if matches!(s.code(), Code::Unauthenticated | Code::PermissionDenied) => {
                    error!("the server refused the worker token: {}", s.message());
                    return Err(WorkerError::Refused(s.message().to_string()));
                }
                Err(s) => {
                    let d = backoff.next();
                    warn!(
                        server = %self.cfg.server,
                        "cannot lease from the server ({:?}: {}); retrying in {:.1} s",
                        s.code(),
                        s.message(),
                        d.as_secs_f64()
                    );
                    pause(d, &mut stop).await;
                }
            }
        }
    }

    /// Run one job with heartbeats, then report it; when the worker drains and the grace period
    /// ends first, stop it and release it instead.
    async fn job(&self, job: pb::Job, stop: &mut watch::Receiver<bool>) {
        let span = info_span!(
            "job",
            job_id = job.job_id,
            run = job.run_id,
            episode = %job.episode_key,
            attempt = job.attempt
        );
        async {
            info!("episode started");
            let _held = crate::metrics::LeaseHeld::new();
            let control = JobControl::with_cores(self.cores.clone());
            let mut done = spawn_episode(job.clone(), self.ctx.clone(), control.clone());
            let mut next = heartbeat_in(job.lease_expires_at_ms);
            let grace = self.cfg.drain_grace();
            // When draining began: the episode may run until `drain + grace`.
            let mut drain = (*stop.borrow()).then(Instant::now);
            let (mut released, mut dropped) = (false, false);
            let (result, video, trace) = loop {
                let cut = drain.map(|t| tokio::time::Instant::from_std(t + grace));
                tokio::select! {
                    r = &mut done => break r.map_or_else(
                        |_| (platform("the episode thread panicked"), None, None),
                        |e| (e.result, e.video, e.trace),
                    ),
                    () = tokio::time::sleep(next) => {
                        next = self.heartbeat(&job, &control, &mut dropped).await;
                    }
                    _ = stop.changed(), if drain.is_none() => {
                        drain = Some(Instant::now());
                        info!(grace_s = grace.as_secs(), "draining: the episode may finish within the grace period");
                    }
                    () = sleep_until_opt(cut), if !released => {
                        released = true;
                        control.cancel("worker draining: grace period over");
                        info!("grace period over: stopping the episode to release it");
                    }
                }
            };
            crate::metrics::episode_ran(&result, dropped, released && control.is_cancelled());
            if dropped {
                info!("result dropped: the server cancelled the lease");
                return;
            }
            if released && control.is_cancelled() {
                self.release(&job, "worker draining: the grace period ended before the episode")
                    .await;
                return;
            }
            info!(
                tasks = result.tasks.len(),
                wall_ms = result.wall_ms,
                platform_error = %result.platform_error,
                "episode finished"
            );
            self.report(&job, result, drain.is_some(), stop).await;
            if let Some(v) = video {
                // Logged inside; the result is in either way.
                let _ = super::upload::upload_video(&self.client, &self.id, &job, v.mp4).await;
            }
            if let Some(t) = trace {
                let gz = tokio::task::spawn_blocking(move || t.to_json_gz()).await.unwrap_or_default();
                super::upload::upload_trace(&self.client, &self.id, &job, gz).await;
            }
        }
        .instrument(span)
        .await;
    }

    /// Give an unfinished job back (draining). Retried briefly; if the server cannot be reached,
    /// the lease expires and its reaper requeues the job.
    async fn release(&self, job: &pb::Job, reason: &str) {
        let req = pb::ReleaseRequest {
            worker_id: self.id.clone(),
            job_id: job.job_id,
            attempt: job.attempt,
            reason: reason.to_string(),
        };
        let give_up_at = Instant::now() + SHUTDOWN_GRACE;
        let mut backoff = Backoff::default();
        loop {
            let mut r = Request::new(req.clone());
            r.set_timeout(Duration::from_secs(5));
            match self.client.clone().release(r).await {
                Ok(a) => {
                    info!(released = a.into_inner().released, "episode released");
                    return;
                }
                Err(s) if !retryable(&s) || Instant::now() >= give_up_at => {
                    warn!(
                        "releasing the job failed ({:?}: {}); the server will requeue it when its lease expires",
                        s.code(),
                        s.message()
                    );
                    return;
                }
                Err(s) => {
                    let d = backoff.next().min(Duration::from_secs(1));
                    warn!(
                        "releasing the job failed ({:?}: {}); retrying",
                        s.code(),
                        s.message()
                    );
                    tokio::time::sleep(d).await;
                }
            }
        }
    }

    /// One heartbeat; returns when the next is due. A cancelled lease stops the episode.
    async fn heartbeat(&self, job: &pb::Job, control: &JobControl, dropped: &mut bool) -> Duration {
        let mut req = Request::new(pb::HeartbeatRequest {
            worker_id: self.id.clone(),
            job_id: job.job_id,
            attempt: job.attempt,
            tasks_done: control.tasks_done(),
            ..Default::default()
        });
        req.set_timeout(Duration::from_secs(10));
        match self.client.clone().heartbeat(req).await {
            Ok(r) => {
                let r = r.into_inner();
                if r.cancelled && !*dropped {
                    *dropped = true;
                    control.cancel("the server cancelled the lease");
                    info!("lease cancelled by the server: stopping the episode");
                }
                heartbeat_in(r.lease_expires_at_ms)
            }
            Err(s) => {
                warn!("heartbeat failed ({:?}: {}); retrying", s.code(), s.message());
                Duration::from_secs(1)
            }
        }
    }

    /// Hand in the result, retrying transport failures (the server dedups on run and episode).
    async fn report(
        &self,
        job: &pb::Job,
        result: pb::EpisodeResult,
        stopping: bool,
        stop: &mut watch::Receiver<bool>,
    ) {
        let req = pb::ReportResultRequest {
            worker_id: self.id.clone(),
            job_id: job.job_id,
            attempt: job.attempt,
            run_id: job.run_id,
            episode_key: job.episode_key.clone(),
            result: Some(result),
        };
        let mut backoff = Backoff::default();
        let mut give_up_at = stopping.then(|| Instant::now() + SHUTDOWN_GRACE);
        loop {
            let mut r = Request::new(req.clone());
            r.set_timeout(Duration::from_secs(10));
            match self.client.clone().report_result(r).await {
                Ok(a) => {
                    let a = a.into_inner();
                    info!(accepted = a.accepted, duplicate = a.duplicate, "result reported");
                    return;
                }
                Err(s) if !retryable(&s) => {
                    warn!(
                        "the server refused the result ({:?}: {}); dropping it",
                        s.code(),
                        s.message()
                    );
                    return;
                }
                Err(s) => {
                    if give_up_at.is_none() && *stop.borrow() {
                        give_up_at = Some(Instant::now() + SHUTDOWN_GRACE);
                    }
                    if give_up_at.is_some_and(|t| Instant::now() >= t) {
                        warn!(
                            "giving up reporting on shutdown; the server will requeue the job when its lease expires"
                        );
                        return;
                    }
                    let d = backoff
                        .next()
                        .min(Duration::from_secs(if stopping { 1 } else { 30 }));
                    warn!(
                        "reporting the result failed ({:?}: {}); retrying in {:.1} s",
                        s.code(),
                        s.message(),
                        d.as_secs_f64()
                    );
                    tokio::time::sleep(d).await;
                }
            }
        }
    }
}

/// How many more episodes the worker takes now. Up to one per core, always; past that, one
/// more at a time, and only when the cores were idle more than `1 - BUSY` of the last window:
/// episodes then spend their time waiting on their policies, and another one would use the idle
/// core. CPU-bound episodes keep the cores busy, so the worker does not hoard jobs another
/// worker could run.
#[derive(Debug)]
struct Pacer {
    cores: Cores,
    limit: usize,
    since: Instant,
    busy_then: f64,
}

impl Pacer {
    fn new(cores: Cores, limit: usize) -> Pacer {
        let busy_then = cores.busy_permit_seconds();
        Pacer {
            cores,
            limit,
            since: Instant::now(),
            busy_then,
        }
    }

    fn room(&mut self, in_flight: usize) -> usize {
        let slots = self.cores.total().min(self.limit);
        if in_flight >= self.limit {
            return 0;
        }
        if in_flight < slots {
            return slots - in_flight;
        }
        let window = self.since.elapsed();
        if window < PACE_WINDOW {
            return 0;
        }
        let busy = self.cores.busy_permit_seconds();
        let share = (busy - self.busy_then) / (slots as f64 * window.as_secs_f64());
        self.since = Instant::now();
        self.busy_then = busy;
        usize::from(share < BUSY)
    }

    /// A lease answered: judge the next one by a window that starts now.
    fn leased(&mut self) {
        self.since = Instant::now();
        self.busy_then = self.cores.busy_permit_seconds();
    }
}

/// Run the episode on a thread of its own; the receiver yields its result.
fn spawn_episode(job: pb::Job, ctx: Arc<JobContext>, control: JobControl) -> oneshot::Receiver<Executed> {
    let (tx, rx) = oneshot::channel();
    let name = format!("episode-{}", job.job_id);
    let spawned = std::thread::Builder::new().name(name).spawn(move || {
        // The trace only when the job wants its video on demand (`execute_job_traced`).
        let _ = tx.send(execute_job_traced(&job, &ctx, &control, false));
    });
    if let Err(e) = spawned {
        // `tx` went with the closure; the dropped sender reads as a platform error.
        error!("cannot start an episode thread: {e}");
    }
    rx
}

fn platform(why: &str) -> pb::EpisodeResult {
    pb::EpisodeResult {
        platform_error: why.to_string(),
        ..Default::default()
    }
}

/// Sleep until `t`, or forever when there is none.
async fn sleep_until_opt(t: Option<tokio::time::Instant>) {
    match t {
        Some(t) => tokio::time::sleep_until(t).await,
        None => std::future::pending().await,
    }
}

/// Sleep for `d` unless asked to stop.
async fn pause(d: Duration, stop: &mut watch::Receiver<bool>) {
    tokio::select! {
        () = tokio::time::sleep(d) => {}
        _ = stop.changed() => {}
    }
}

/// Capped exponential backoff from 250 ms.
#[derive(Debug, Default)]
struct Backoff(u32);

impl Backoff {
    fn next(&mut self) -> Duration {
        let d = Duration::from_millis(250u64 << self.0.min(7)).min(MAX_BACKOFF);
        self.0 += 1;
        d
    }
    fn reset(&mut self) {
        self.0 = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_up_to_the_cap() {
        let mut b = Backoff::default();
        let v: Vec<u64> = (0..10).map(|_| b.next().as_millis() as u64).collect();
        assert_eq!(&v[..4], &[250, 500, 1000, 2000]);
        assert_eq!(*v.last().unwrap(), 30_000);
        b.reset();
        assert_eq!(b.next(), Duration::from_millis(250));
    }
}
