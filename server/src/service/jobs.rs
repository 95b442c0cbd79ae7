//! The worker-facing queue: lease (long-polled), heartbeat, result reports and the reaper.
//!
//! Policy:
//! - workers authenticate with the worker token; a lease is `(job, attempt, owner)`;
//! - a report quoting an older attempt is refused (`accepted = false`), a second report of an
//!   already recorded `(run, episode)` is acknowledged as a duplicate and changes nothing;
//! - a released lease (a draining worker gives back what it could not finish) requeues the job
//!   at once and does not count as an attempt;
//! - a report with `platform_error` set (or an expired lease) requeues the job without
//!   recording anything against the participant; after `max_attempts` leases the episode is
//!   recorded as failed with the reason, so a run always finishes;
//! - the report (or reap) that closes a run's last job computes the run's scores in the same
//!   transaction, so a crash can never leave a finished run unscored or scored twice.

use std::collections::BTreeSet;
use std::time::Duration;

use serde::Serialize;
use tokio::time::Instant;

use self::checks::MAX_REASON_CHARS;
use super::lease::{HeartbeatOutcome, MAX_JOBS_PER_LEASE, MAX_LEASE_WAIT_MS};
use super::metrics::record;
use super::renders::LeasedRender;
use super::{AppState, WorkerCred, now_ms};
use crate::episodes::{JobSpec, TaskOutcome};
use crate::error::ServiceError;
use crate::states::JobState;
use crate::store::queue::{self, NewResult};

/// Cap of the stored log tail (worker.proto: 64 KiB).
pub(crate) const MAX_LOG_TAIL_BYTES: usize = 64 << 10;
const MAX_TASKS: usize = 256;
/// A long-polling Lease re-checks the queue this often even without a wake-up, so a slot freed
/// by another process's write is not missed.
const POLL_INTERVAL: Duration = Duration::from_millis(500);

/// A job as handed to a worker.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LeasedJob {
    pub id: i64,
    pub attempt: u32,
    pub lease_expires_at_ms: i64,
    pub run_id: i64,
    pub episode_key: String,
    pub spec: JobSpec,
    /// What the policy endpoint sees as `episode_id`: random per lease, so it names neither
    /// the instruction nor the run.
    pub policy_episode_id: String,
}

/// A worker's result report.
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct Report {
    pub worker_id: String,
    pub job_id: i64,
    pub attempt: u32,
    pub run_id: i64,
    pub episode_key: String,
    pub tasks: Vec<TaskOutcome>,
    pub platform_error: String,
    pub log_tail: String,
    pub wall_ms: u64,
    /// Where the robot went (online episodes; checked in [`crate::plots::from_report`]).
    pub path: Option<kitchen_r_core::topdown::PathPlot>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub(crate) struct ReportOutcome {
    pub accepted: bool,
    pub duplicate: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub(crate) struct ReapReport {
    pub requeued: usize,
    pub failed: usize,
    pub runs_finished: usize,
}

impl AppState {
    /// The server is shutting down: answer waiting leases now, empty, and lease nothing more.
    pub(crate) fn begin_shutdown(&self) {
        self.inner
            .stopping
            .store(true, std::sync::atomic::Ordering::SeqCst);
        self.inner.jobs_ready.notify_waiters();
    }

    pub(super) fn lease_ms(&self) -> i64 {
        i64::try_from(self.config().control.lease_s.saturating_mul(1000)).unwrap_or(i64::MAX / 2)
    }

    /// Claim up to `max_jobs` evaluation jobs for `worker_id`, waiting up to `wait_ms` for work
    /// (the tests' way in; workers call [`Self::lease_work`]).
    #[cfg(test)]
    pub(crate) async fn lease(
        &self,
        cred: WorkerCred,
        worker_id: &str,
        max_jobs: u32,
        wait_ms: u32,
    ) -> Result<Vec<LeasedJob>, ServiceError> {
        Ok(self
            .lease_work(cred, worker_id, max_jobs, wait_ms, false)
            .await?
            .0)
    }

    /// As `Self::lease`; with `renders`, a video render (`super::renders`) when no evaluation
    /// job is queued: the lowest priority, one per call.
    pub(crate) async fn lease_work(
        &self,
        _: WorkerCred,
        worker_id: &str,
        max_jobs: u32,
        wait_ms: u32,
        renders: bool,
    ) -> Result<(Vec<LeasedJob>, Option<LeasedRender>), ServiceError> {
        let worker = validate_worker_id(worker_id)?;
        if !(1..=MAX_JOBS_PER_LEASE).contains(&max_jobs) {
            return Err(ServiceError::BadRequest(format!(
                "max_jobs must be between 1 and {MAX_JOBS_PER_LEASE}"
            )));
        }
        self.worker_seen(worker);
        let deadline = Instant::now() + Duration::from_millis(u64::from(wait_ms.min(MAX_LEASE_WAIT_MS)));
        loop {
            // Registered before the claim so a wake-up between claim and wait is not lost.
            let notified = self.inner.jobs_ready.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            // No new leases while stopping: the results could not be reported to this process.
            if self.inner.stopping.load(std::sync::atomic::Ordering::SeqCst) {
                return Ok((Vec::new(), None));
            }
            let now = now_ms();
            // A read first: idle workers polling must not take the write lock every time.
            let claimed = match queue::any_queued(self.pool()).await? {
                true => {
                    let team_cap = self.config().control.max_in_flight_per_team;
                    queue::claim(
                        self.pool(),
                        worker,
                        now,
                        now + self.lease_ms(),
                        max_jobs,
                        team_cap,
                    )
                    .await?
                }
                false => Vec::new(),
            };
            let render = match renders && claimed.is_empty() {
                true => self.claim_render(worker).await?,
                false => None,
            };
            if !claimed.is_empty() || render.is_some() || Instant::now() >= deadline {
                self.worker_seen(worker);
                self.record_queue_waits(&claimed, now).await;
                let jobs = self.hand_out(claimed, worker).await?;
                for j in &jobs {
                    tracing::info!(job = j.id, run = j.run_id, episode = %j.episode_key, attempt = j.attempt, worker, "job leased");
                }
                return Ok((jobs, render));
            }
            let _ = tokio::time::timeout_at(deadline.min(Instant::now() + POLL_INTERVAL), notified).await;
        }
    }

    /// Extend a lease the worker still holds.
    pub(crate) async fn heartbeat(
        &self,
        _: WorkerCred,
        worker_id: &str,
        job_id: i64,
        attempt: u32,
    ) -> Result<HeartbeatOutcome, ServiceError> {
        let worker = validate_worker_id(worker_id)?;
        self.worker_seen(worker);
        let now = now_ms();
        let until = queue::heartbeat(
            self.pool(),
            job_id,
            i64::from(attempt),
            worker,
            now + self.lease_ms(),
            now,
        )
        .await?;
        if until.is_none() {
            tracing::info!(
                job = job_id,
                attempt,
                worker,
                "heartbeat for a lease no longer held: cancelled"
            );
        }
        Ok(HeartbeatOutcome {
            lease_expires_at_ms: until,
        })
    }

    /// Give back a lease unfinished (a draining worker): the job is queued again at once without
    /// using an attempt, and long-polling leases wake up to take it. `false` when the caller no
    /// longer holds that lease (nothing changes).
    pub(crate) async fn release(
        &self,
        _: WorkerCred,
        worker_id: &str,
        job_id: i64,
        attempt: u32,
        reason: &str,
    ) -> Result<bool, ServiceError> {
        let worker = validate_worker_id(worker_id)?;
        let reason = match reason.trim() {
            "" => "released by the worker".to_string(),
            r => format!("released: {}", checks::cap_text(r, MAX_REASON_CHARS)),
        };
        let released =
            queue::release(self.pool(), job_id, i64::from(attempt), worker, &reason, now_ms()).await?;
        if released {
            self.after_queue_write(false);
        }
        tracing::info!(job = job_id, attempt, worker, released, %reason, "lease released");
        Ok(released)
    }

    /// Record one episode's result (idempotent on `(run, episode)`).
    pub(crate) async fn report_result(
        &self,
        _: WorkerCred,
        mut r: Report,
    ) -> Result<ReportOutcome, ServiceError> {
        validate_worker_id(&r.worker_id)?;
        if r.tasks.len() > MAX_TASKS {
            return Err(ServiceError::BadRequest(format!(
                "at most {MAX_TASKS} task results per episode"
            )));
        }
        r.log_tail = checks::cap_log_lines(tail(&r.log_tail, MAX_LOG_TAIL_BYTES));
        checks::cap_reasons(&mut r.tasks);
        let now = now_ms();
        let mut tx = self.pool().begin_with("BEGIN IMMEDIATE").await?;
        let job = queue::job(&mut tx, r.job_id)
            .await?
            .ok_or_else(|| ServiceError::not_found(format!("job {}", r.job_id)))?;
        if job.run_id != r.run_id || job.episode_key != r.episode_key {
            return Err(ServiceError::BadRequest(format!(
                "job {} is episode {:?} of run {}, not {:?} of run {}",
                job.id, job.episode_key, job.run_id, r.episode_key, r.run_id
            )));
        }
        // Only a result's tasks are recorded; a platform error's are not looked at.
        if r.platform_error.trim().is_empty() {
            checks::check_tasks(&r.tasks, &job.spec).map_err(|why| {
                tracing::warn!(job = job.id, worker = %r.worker_id, %why, "report refused");
                ServiceError::BadRequest(format!("job {} (episode {:?}): {why}", job.id, job.episode_key))
            })?;
        }
        if queue::result_exists(&mut tx, job.run_id, &job.episode_key).await? {
            return Ok(ReportOutcome {
                accepted: true,
                duplicate: true,
            });
        }
        // A requeued job keeps its attempt until leased again, so its last holder may still
        // hand the result in; any other state or attempt is stale.
        let current = i64::from(r.attempt) == job.attempt && job.state.is_open();
        if !current {
            tracing::info!(job = job.id, attempt = r.attempt, current = job.attempt, state = %job.state, "stale report refused");
            return Ok(ReportOutcome {
                accepted: false,
                duplicate: false,
            });
        }
        // Whether the platform gave up on the job, when the attempt failed (for /metrics).
        let mut gave_up = None;
        if r.platform_error.trim().is_empty() {
            let result = NewResult {
                job: &job,
                mode: job.spec.mode.as_str(),
                tasks: &r.tasks,
                failure: None,
                wall_ms: i64::try_from(r.wall_ms).unwrap_or(i64::MAX),
                log_tail: &r.log_tail,
                worker_id: &r.worker_id,
                // Only an online episode has a path to plot.
                path: r
                    .path
                    .as_ref()
                    .filter(|_| job.spec.mode == crate::episodes::Mode::Online),
            };
            queue::insert_result(&mut tx, &result, now).await?;
            queue::close_job(&mut tx, job.id, JobState::Done, None, now).await?;
        } else {
            let reason = format!(
                "platform error: {}",
                checks::cap_text(r.platform_error.trim(), MAX_REASON_CHARS)
            );
            gave_up = Some(
                self.retry_or_fail(&mut tx, &job, &reason, &r.worker_id, now)
                    .await?,
            );
        }
        let finished = self.finish_if_done(&mut tx, job.run_id, now).await?;
        tx.commit().await?;
        match gave_up {
            None => record::episode_done(job.spec.mode.as_str(), r.wall_ms),
            Some(failed) => record::attempt_failed("platform_error", failed),
        }
        self.after_queue_write(finished);
        tracing::info!(job = job.id, run = job.run_id, episode = %job.episode_key, finished, "result reported");
        Ok(ReportOutcome {
            accepted: true,
            duplicate: false,
        })
    }

    /// Requeue every job whose lease ended before `now`, or record it as failed once it has
    /// had all its attempts.
    pub(crate) async fn reap_expired(&self, now: i64) -> Result<ReapReport, ServiceError> {
        let mut report = ReapReport::default();
        self.reap_renders(now).await?;
        // A cheap read first, so the periodic reaper takes the write lock only when needed.
        if queue::expired(&mut *self.pool().acquire().await?, now)
            .await?
            .is_empty()
        {
            return Ok(report);
        }
        let mut tx = self.pool().begin_with("BEGIN IMMEDIATE").await?;
        let mut runs = BTreeSet::new();
        for job in queue::expired(&mut tx, now).await? {
            let owner = job.lease_owner.clone().unwrap_or_default();
            let reason = format!("lease expired: worker {owner:?} stopped reporting");
            if self.retry_or_fail(&mut tx, &job, &reason, &owner, now).await? {
                report.failed += 1;
                runs.insert(job.run_id);
            } else {
                report.requeued += 1;
            }
        }
        for run in runs {
            report.runs_finished += usize::from(self.finish_if_done(&mut tx, run, now).await?);
        }
        tx.commit().await?;
        record::reaped(report.requeued, report.failed);
        self.after_queue_write(report.runs_finished > 0);
        tracing::info!(?report, "expired leases reaped");
        Ok(report)
    }

    /// Wake long-polling leases: there is work (a render was queued).
    pub(crate) fn wake_leases(&self) {
        self.inner.jobs_ready.notify_waiters();
    }

    /// Wake long-polling leases (a job was requeued or a concurrency slot freed) and drop the
    /// cached leaderboards when a run got its scores.
    fn after_queue_write(&self, run_finished: bool) {
        self.inner.jobs_ready.notify_waiters();
        if run_finished {
            self.leaderboard_cache().invalidate();
        }
    }
}

fn validate_worker_id(id: &str) -> Result<&str, ServiceError> {
    let id = id.trim();
    if id.is_empty() || id.len() > 200 || id.chars().any(char::is_control) {
        return Err(ServiceError::BadRequest(
            "worker_id must be 1 to 200 printable characters (host name and pid, say)".into(),
        ));
    }
    Ok(id)
}

/// The last `max` bytes of `s`, cut at a character boundary.
fn tail(s: &str, max: usize) -> &str {
    if s.len() <= max {
        return s;
    }
    let mut start = s.len() - max;
    while !s.is_char_boundary(start) {
        start += 1;
    }
    &s[start..]
}

mod checks;
mod finish;
mod handout;
#[cfg(test)]
mod tests;
