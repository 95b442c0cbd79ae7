//! The organiser's console (docs/organiser-console.md): the queue by state with the oldest queued
//! job's age and each team's share, the workers with their last heartbeat and current episodes, the
//! policy runs with progress and an ETA, stuck and failed jobs with their reasons; cancelling
//! and requeueing a run; and a consistent copy of the live database.
//!
//! Policy:
//! - every method takes the [`Organiser`] proof; team names appear here (organiser only);
//! - cancelling marks the run `cancelled` with who and when in the transaction that cancels its
//!   jobs and refreshes its leaderboard entries; a cancelled run uses no quota (the quota count
//!   skips it) and ranks nowhere; a worker still simulating one of its episodes learns at its
//!   next heartbeat (the lease is gone) and its late report is refused as stale;
//! - requeueing puts failed and stuck jobs back in the queue with their full number of attempts
//!   again; it never touches a cancelled run (submit again, or `rescore --resimulate`);
//! - the backup is `VACUUM INTO` a fresh file next to the database, streamed back and deleted:
//!   the organiser never names a path on the server, and the server keeps serving meanwhile.
//!
//! Workers are known by their leases and recorded results (see [`crate::store::admin`]): a
//! worker that has held no lease and reported nothing for [`WORKER_WINDOW_MS`] is not listed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use kitchen_r_core::observations::ObservationTrack;
use serde::Serialize;

use super::{AppState, Organiser, now_ms, rfc3339};
use crate::error::ServiceError;
use crate::states::{JobState, RunState};
use crate::store::admin::{self as store, RunOp};

/// Workers seen (a lease or a result) within this window are listed.
pub(crate) const WORKER_WINDOW_MS: i64 = 24 * 3_600_000;
/// Finished and cancelled runs listed after the active ones.
const RECENT_RUNS: i64 = 50;
/// Problem jobs listed, most recently changed first.
const PROBLEM_JOBS: i64 = 200;
/// Who a cancellation is recorded as (there is one organiser token).
const ORGANISER: &str = "organiser";

/// `GET /api/v1/admin/queue`.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct QueueView {
    pub at: String,
    /// Jobs by state: queued, leased, done, failed, cancelled.
    pub jobs: BTreeMap<&'static str, i64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub oldest_queued_at: Option<String>,
    /// How long the oldest queued job has waited since it was queued, in seconds.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub oldest_queued_age_s: Option<f64>,
    /// Each team's share of the episodes in flight, most first; only teams with open jobs.
    pub teams: Vec<TeamShare>,
    /// Leased past expiry: the worker stopped heartbeating; the reaper will requeue them.
    pub stuck: Vec<JobView>,
    /// Queued or leased again after a failed attempt.
    pub retrying: Vec<JobView>,
    /// The platform gave up on them after their attempts (`admin requeue RUN` retries them).
    pub failed: Vec<JobView>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct TeamShare {
    pub team: String,
    pub in_flight: i64,
    pub queued: i64,
    pub runs: i64,
    /// `in_flight` over all episodes in flight (0 when none is).
    pub share: f64,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct JobView {
    pub job: i64,
    pub run: i64,
    pub team: String,
    pub episode: String,
    pub state: JobState,
    pub attempt: i64,
    pub max_attempts: i64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worker: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lease_expires_at: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    pub updated_at: String,
}

/// `GET /api/v1/admin/workers`.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct WorkersView {
    pub at: String,
    pub workers: Vec<WorkerView>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct WorkerView {
    pub worker: String,
    /// The later of its last lease or heartbeat and its last report.
    pub last_seen: String,
    pub last_seen_age_s: f64,
    /// Last lease grant or heartbeat of a lease it holds now.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_heartbeat: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_report: Option<String>,
    /// Episodes it recorded in the last 24 hours.
    pub episodes_24h: i64,
    /// The episodes it holds leases on now.
    pub current: Vec<CurrentEpisode>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct CurrentEpisode {
    pub job: i64,
    pub run: i64,
    pub episode: String,
    pub attempt: i64,
    pub lease_expires_at: String,
    /// The lease ran out without a heartbeat.
    pub expired: bool,
}

/// `GET /api/v1/admin/runs`.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct RunsView {
    pub at: String,
    pub runs: Vec<RunView>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
#[schema(as = AdminRunView)]
pub(crate) struct RunView {
    pub run: i64,
    pub submission: i64,
    pub team: String,
    pub split: String,
    /// The board its scores go to: `privileged` when its policy asked for, and received,
    /// privileged observations (ranked apart from `standard` runs). Every run listed here is a
    /// policy run: plan files are scored at upload and have no run to watch.
    #[schema(value_type = crate::schema::ObservationsName)]
    pub observations: ObservationTrack,
    pub state: RunState,
    pub episodes_total: i64,
    /// Episodes with a recorded result (including `episodes_gave_up`).
    pub episodes_done: i64,
    /// Episodes the platform gave up on.
    pub episodes_gave_up: i64,
    pub episodes_running: i64,
    pub episodes_queued: i64,
    /// `episodes_done / episodes_total`.
    pub progress: f64,
    pub created_at: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub started_at: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub finished_at: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cancelled_at: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cancelled_by: Option<String>,
    /// Mean wall time of its episodes that ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_episode_s: Option<f64>,
    /// Active runs: when it should finish at the pace so far (elapsed since its first episode
    /// started, per recorded episode, times the episodes left).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eta: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub eta_s: Option<f64>,
}

/// The answer to a cancel.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Cancelled {
    pub run: i64,
    pub state: RunState,
    pub cancelled_at: String,
    pub cancelled_by: &'static str,
    /// Queued and leased jobs cancelled.
    pub jobs_cancelled: u64,
    /// Of which a worker held: it stops at its next heartbeat.
    pub leases_revoked: i64,
}

/// The answer to a requeue.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub(crate) struct Requeued {
    pub run: i64,
    /// Failed and stuck jobs put back in the queue.
    pub jobs_requeued: u64,
    /// Of which were stuck (leased past expiry).
    pub stuck: i64,
    /// The attempts each open job of the run has again.
    pub attempts: u32,
}

/// Everything the console page shows.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Console {
    pub queue: QueueView,
    pub workers: WorkersView,
    pub runs: RunsView,
    /// `admin verify`'s stored verdicts: a run marked unverified shows it.
    pub verifications: Vec<super::verification::Verdict>,
}

/// A consistent copy of the database, open and already unlinked from the file system (Unix):
/// reading it to the end streams the copy; dropping it frees the space.
#[derive(Debug)]
pub(crate) struct Backup {
    pub file: tokio::fs::File,
    pub len: u64,
    /// Suggested file name: `kitchen-r-<UTC time>.db`.
    pub name: String,
}

impl AppState {
    pub(crate) async fn admin_queue(&self, _: Organiser) -> Result<QueueView, ServiceError> {
        let now = now_ms();
        let pool = self.read_pool();
        let c = store::queue_counts(pool).await?;
        let loads = store::team_loads(pool).await?;
        let problems = store::problem_jobs(pool, now, PROBLEM_JOBS).await?;
        let total_in_flight: i64 = loads.iter().map(|l| l.in_flight).sum();
        let teams = loads
            .into_iter()
            .map(|l| TeamShare {
                share: if total_in_flight > 0 {
                    l.in_flight as f64 / total_in_flight as f64
                } else {
                    0.0
                },
                team: l.team,
                in_flight: l.in_flight,
                queued: l.queued,
                runs: l.runs,
            })
            .collect();
        let (mut stuck, mut retrying, mut failed) = (Vec::new(), Vec::new(), Vec::new());
        for p in problems {
            let is_stuck = p.state == JobState::Leased && p.lease_expires_at.is_some_and(|t| t < now);
            let view = JobView {
                job: p.id,
                run: p.run_id,
                team: p.team,
                episode: p.episode_key,
                state: p.state,
                attempt: p.attempt,
                max_attempts: p.max_attempts,
                worker: p.lease_owner,
                lease_expires_at: p.lease_expires_at.map(rfc3339),
                reason: p.last_error,
                updated_at: rfc3339(p.updated_at),
            };
            match p.state {
                JobState::Failed => failed.push(view),
                _ if is_stuck => stuck.push(view),
                _ => retrying.push(view),
            }
        }
        let jobs = BTreeMap::from([
            ("queued", c.queued),
            ("leased", c.leased),
            ("done", c.done),
            ("failed", c.failed),
            ("cancelled", c.cancelled),
        ]);
        Ok(QueueView {
            at: rfc3339(now),
            jobs,
            oldest_queued_at: c.oldest_queued_at.map(rfc3339),
            oldest_queued_age_s: c.oldest_queued_at.map(|t| secs(now - t)),
            teams,
            stuck,
            retrying,
            failed,
        })
    }

    pub(crate) async fn admin_workers(&self, _: Organiser) -> Result<WorkersView, ServiceError> {
        let now = now_ms();
        let pool = self.read_pool();
        let leases = store::held_leases(pool).await?;
        let reports = store::worker_reports(pool, now - WORKER_WINDOW_MS).await?;
        let mut by_worker: BTreeMap<String, WorkerAcc> = BTreeMap::new();
        for l in leases {
            let w = by_worker.entry(l.worker).or_default();
            w.heartbeat = w.heartbeat.max(Some(l.updated_at));
            w.current.push(CurrentEpisode {
                job: l.job_id,
                run: l.run_id,
                episode: l.episode_key,
                attempt: l.attempt,
                lease_expires_at: rfc3339(l.lease_expires_at),
                expired: l.lease_expires_at < now,
            });
        }
        for r in reports {
            let w = by_worker.entry(r.worker).or_default();
            w.report = Some(r.last_report_at);
            w.episodes = r.episodes;
        }
        let mut workers: Vec<WorkerView> = by_worker
            .into_iter()
            .map(|(worker, w)| {
                let seen = w.heartbeat.max(w.report).unwrap_or(now);
                WorkerView {
                    worker,
                    last_seen: rfc3339(seen),
                    last_seen_age_s: secs(now - seen),
                    last_heartbeat: w.heartbeat.map(rfc3339),
                    last_report: w.report.map(rfc3339),
                    episodes_24h: w.episodes,
                    current: w.current,
                }
            })
            .collect();
        // Busy workers first, then the most recently seen.
        workers.sort_by(|a, b| {
            b.current
                .len()
                .cmp(&a.current.len())
                .then(a.last_seen_age_s.total_cmp(&b.last_seen_age_s))
                .then_with(|| a.worker.cmp(&b.worker))
        });
        Ok(WorkersView {
            at: rfc3339(now),
            workers,
        })
    }

    pub(crate) async fn admin_runs(&self, _: Organiser) -> Result<RunsView, ServiceError> {
        let now = now_ms();
        let runs = store::runs(self.read_pool(), RECENT_RUNS)
            .await?
            .into_iter()
            .map(|r| run_view(r, now))
            .collect();
        Ok(RunsView {
            at: rfc3339(now),
            runs,
        })
    }

    /// The queue, workers and runs together (the console page).
    pub(crate) async fn admin_console(&self, admin: Organiser) -> Result<Console, ServiceError> {
        Ok(Console {
            queue: self.admin_queue(admin).await?,
            workers: self.admin_workers(admin).await?,
            runs: self.admin_runs(admin).await?,
            verifications: self.verdicts().await?,
        })
    }

    /// Stop an active policy run and give its team the quota back.
    pub(crate) async fn cancel_run(&self, _: Organiser, run: i64) -> Result<Cancelled, ServiceError> {
        let now = now_ms();
        match store::cancel_run(self.pool(), run, ORGANISER, now).await? {
            RunOp::Done { jobs, were_leased } => {
                // Leases freed: waiting workers may take other runs' jobs now.
                self.inner.jobs_ready.notify_waiters();
                self.leaderboard_cache().invalidate();
                tracing::warn!(run, jobs, leases = were_leased, by = ORGANISER, "run cancelled");
                Ok(Cancelled {
                    run,
                    state: RunState::Cancelled,
                    cancelled_at: rfc3339(now),
                    cancelled_by: ORGANISER,
                    jobs_cancelled: jobs,
                    leases_revoked: were_leased,
                })
            }
            other => Err(refused(
                run,
                other,
                "cancelled",
                "only an active run can be cancelled",
            )),
        }
    }

    /// Put a run's failed and stuck jobs back in the queue, with their attempts reset.
    pub(crate) async fn requeue_run(&self, _: Organiser, run: i64) -> Result<Requeued, ServiceError> {
        let now = now_ms();
        let attempts = self.config().control.max_attempts;
        match store::requeue_run(self.pool(), run, i64::from(attempts), now).await? {
            RunOp::Done { jobs, were_leased } => {
                self.inner.jobs_ready.notify_waiters();
                self.leaderboard_cache().invalidate();
                tracing::warn!(run, jobs, stuck = were_leased, by = ORGANISER, "run requeued");
                Ok(Requeued {
                    run,
                    jobs_requeued: jobs,
                    stuck: were_leased,
                    attempts,
                })
            }
            other => Err(refused(
                run,
                other,
                "requeued",
                "a cancelled run stays cancelled: submit again or `rescore --resimulate`",
            )),
        }
    }

    /// A consistent copy of the live database, for `POST /api/v1/admin/backup`.
    pub(crate) async fn backup(&self, _: Organiser) -> Result<Backup, ServiceError> {
        let now = now_ms();
        let path = backup_path(&self.config().db)?;
        let result = store::vacuum_into(self.read_pool(), &path).await;
        let opened = match result {
            Ok(()) => tokio::fs::File::open(&path).await,
            Err(e) => {
                let _ = std::fs::remove_file(&path);
                return Err(anyhow::Error::from(e)
                    .context("VACUUM INTO the backup file")
                    .into());
            }
        };
        // The open file keeps its data until it is closed: unlink it now, so nothing is left
        // behind whatever happens to the response.
        let removed = std::fs::remove_file(&path);
        let file = opened.map_err(|e| anyhow::Error::from(e).context("opening the backup copy"))?;
        if let Err(e) = removed {
            tracing::warn!(path = %path.display(), error = %e, "could not remove the backup copy");
        }
        let len = file
            .metadata()
            .await
            .map_err(|e| anyhow::Error::from(e).context("reading the backup copy"))?
            .len();
        let stamp: String = rfc3339(now)
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .collect();
        tracing::info!(bytes = len, by = ORGANISER, "database backup taken");
        Ok(Backup {
            file,
            len,
            name: format!("kitchen-r-{stamp}.db"),
        })
    }
}

#[derive(Default)]
struct WorkerAcc {
    heartbeat: Option<i64>,
    report: Option<i64>,
    episodes: i64,
    current: Vec<CurrentEpisode>,
}

fn secs(ms: i64) -> f64 {
    ms.max(0) as f64 / 1000.0
}

fn run_view(r: store::RunProgress, now: i64) -> RunView {
    let left = (r.episodes_total - r.done).max(0);
    let eta_ms = match (r.state, r.started_at) {
        (RunState::Active, Some(started)) if r.done > 0 && left > 0 => {
            let per_episode = (now - started).max(0) as f64 / r.done as f64;
            Some(per_episode * left as f64)
        }
        (RunState::Active, _) if left == 0 => Some(0.0),
        _ => None,
    };
    RunView {
        run: r.id,
        submission: r.submission_id,
        team: r.team,
        split: r.split,
        observations: ObservationTrack::of(r.privileged),
        state: r.state,
        episodes_total: r.episodes_total,
        episodes_done: r.done,
        episodes_gave_up: r.gave_up,
        episodes_running: r.running,
        episodes_queued: r.queued,
        progress: if r.episodes_total > 0 {
            r.done as f64 / r.episodes_total as f64
        } else {
            0.0
        },
        created_at: rfc3339(r.created_at),
        started_at: r.started_at.map(rfc3339),
        finished_at: r.finished_at.map(rfc3339),
        cancelled_at: r.cancelled_at.map(rfc3339),
        cancelled_by: r.cancelled_by,
        mean_episode_s: r.mean_episode_ms.map(|ms| ms / 1000.0),
        eta: eta_ms.map(|ms| rfc3339(now + ms as i64)),
        eta_s: eta_ms.map(|ms| ms / 1000.0),
    }
}

fn refused(run: i64, op: RunOp, verb: &str, rule: &str) -> ServiceError {
    match op {
        RunOp::NoSuchRun => ServiceError::not_found(format!("run {run}")),
        RunOp::NotPolicy => ServiceError::Conflict(format!(
            "run {run} scores a plan file: it has no episodes to be {verb}"
        )),
        RunOp::WrongState(state) => {
            ServiceError::Conflict(format!("run {run} is {}: {rule}", state.as_str()))
        }
        RunOp::Done { .. } => {
            ServiceError::Internal(anyhow::anyhow!("refused a run operation that succeeded"))
        }
    }
}

/// A fresh, unused file name next to the database (same file system and permissions as the
/// database itself), or in the temporary directory for an in-memory database.
fn backup_path(db_url: &str) -> Result<PathBuf, ServiceError> {
    let opts = sqlx::sqlite::SqliteConnectOptions::from_str(db_url)
        .map_err(|e| anyhow::anyhow!("bad database URL {db_url:?}: {e}"))?;
    let db = opts.get_filename();
    let name = db.file_name().map(|n| n.to_string_lossy().into_owned());
    let dir = match (db.parent(), &name) {
        (Some(d), Some(n)) if n != ":memory:" && !db_url.contains("mode=memory") => {
            if d.as_os_str().is_empty() {
                Path::new(".").to_path_buf()
            } else {
                d.to_path_buf()
            }
        }
        _ => std::env::temp_dir(),
    };
    let random: [u8; 8] = rand::random();
    let base = name.unwrap_or_else(|| "kitchen-r.db".into());
    Ok(dir.join(format!(".{base}.backup-{}.tmp", hex::encode(random))))
}

#[cfg(test)]
mod tests;
