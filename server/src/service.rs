//! The service layer: every rule of the server (authentication, quotas, validation, scoring,
//! leaderboard order) lives here, once. The HTTP and gRPC adapters only translate requests and
//! answers; they call these functions and nothing below them.
//!
//! `AppState`'s methods are grouped by responsibility, one submodule each:
//! - [`auth`]: who is calling (a bearer token resolved once into a `Caller` and its proofs);
//! - [`teams`]: the organiser creates teams;
//! - [`plan_uploads`]: plan files validated, scored and stored within the daily quota;
//! - [`limits`]: the per-team upload rate limit and the counts of refused uploads;
//! - [`metrics`]: what `GET /metrics` reads when scraped (queue gauges, workers seen);
//! - [`policies`]: policy endpoints probed and registered, their episodes queued;
//! - [`jobs`]: the worker-facing queue (lease, heartbeat, report, reaper);
//! - [`progress`]: a policy run's episodes and failures as its team may see them;
//! - [`submissions`]: a submission with its latest run, for its team or the organiser;
//! - [`board`]: the leaderboards, cached and rendered;
//! - [`portal`]: what the participant pages read (a team's submissions, quota left, ETA);
//! - [`rescore`]: the organiser's rescoring of every stored submission;
//! - [`secrets`]: endpoint tokens sealed at rest, opened for workers, sealed at start-up;
//! - [`admin`]: the organiser's console (queue, workers, runs; cancel, requeue, backup);
//! - [`archive`]: the contest archive, exported and imported whole (docs/contest/archive.md);
//! - [`verification`]: replay verdicts on runs and the material to verify and re-evaluate them;
//! - [`video_budget`]: the video storage budgets and the files nothing links any more;
//! - [`videos`]: episode videos and traces stored by content, served, swept after retention.
//!
//! This file holds only the shared state and its accessors.

pub(crate) mod admin;
pub(crate) mod archive;
pub(crate) mod auth;
mod board;
pub(crate) mod jobs;
pub(crate) mod lease;
mod limits;
mod login_throttle;
mod metrics;
mod plan_uploads;
pub(crate) mod policies;
pub(crate) mod portal;
mod progress;
pub(crate) mod renders;
mod rescore;
mod secrets;
pub(crate) mod sessions;
mod submissions;
mod teams;
pub(crate) mod verification;
mod video_budget;
pub(crate) mod videos;
pub(crate) mod volume;

use std::sync::Arc;

use sqlx::sqlite::SqlitePool;

use crate::config::Config;
use crate::content::Content;
use crate::leaderboard::LeaderboardCache;
use crate::probe::PolicyProbe;
use crate::store::Db;

pub(crate) use crate::clock::{now_ms, rfc3339};
pub(crate) use crate::scores::Scores;
pub(crate) use auth::{Caller, Organiser, WorkerCred, hash_token, new_token};
pub(crate) use policies::RegisterPolicy;
pub(crate) use progress::{EpisodeView, PolicyRunView};
pub(crate) use submissions::{RunView, SubmissionView};
// Answers of HTTP routes, named by the OpenAPI document (`http::openapi`).
pub(crate) use {limits::AdminStats, plan_uploads::Submitted, rescore::RescoreReport, teams::NewTeam};

/// Version of the planning scorer; part of every scoring run's `scorer_version`.
pub(crate) const PLANNING_SCORER: &str = "planning-em/1";

/// Shared state of the server: a cheap `Clone` handle that every adapter holds.
#[derive(Clone)]
pub(crate) struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    db: Db,
    config: Config,
    content: Content,
    admin_hash: String,
    /// Serialises quota check + insert so two concurrent uploads cannot both take the last slot.
    submit_lock: tokio::sync::Mutex<()>,
    leaderboard: LeaderboardCache,
    worker_hash: String,
    probe: Arc<dyn PolicyProbe>,
    /// Woken whenever jobs become available, so long-polling `Lease` calls answer at once.
    jobs_ready: tokio::sync::Notify,
    /// Set at shutdown so long-polling `Lease` calls answer at once instead of holding the
    /// graceful drain for up to 30 s.
    stopping: std::sync::atomic::AtomicBool,
    /// Per-team upload rate limits and refusal counts (in memory: see [`limits`]).
    limits: limits::Limits,
    /// Failed page logins per client address (in memory: see [`login_throttle`]).
    logins: login_throttle::LoginThrottle,
    /// What `/metrics` reads when scraped (workers seen, cached queue gauges).
    telemetry: metrics::Telemetry,
    /// Seals policy endpoints' bearer tokens at rest ([`secrets`]).
    secret_key: crate::secrets::SecretKey,
    /// Video uploads in flight and the lock ordering file decisions (see [`video_budget`]).
    videos: video_budget::VideoLedger,
}

impl std::fmt::Debug for AppState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AppState").finish_non_exhaustive()
    }
}

/// The secrets an [`AppState`] checks callers against.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Tokens<'a> {
    /// The organiser's token.
    pub admin: &'a str,
    /// The token simulation workers present on the `Worker` gRPC service.
    pub worker: &'a str,
    /// The key that seals endpoint tokens at rest (`[secrets] key_file`).
    pub secret_key: &'a crate::secrets::SecretKey,
}

impl AppState {
    pub(crate) fn new(
        db: Db,
        config: Config,
        content: Content,
        tokens: Tokens<'_>,
        probe: Arc<dyn PolicyProbe>,
    ) -> AppState {
        AppState {
            inner: Arc::new(Inner {
                db,
                limits: limits::Limits::new(config.quota.per_minute, now_ms()),
                telemetry: metrics::Telemetry::new(),
                logins: login_throttle::LoginThrottle::new(config.sessions.failures_per_minute_per_address),
                config,
                content,
                admin_hash: hash_token(tokens.admin),
                submit_lock: tokio::sync::Mutex::new(()),
                leaderboard: LeaderboardCache::default(),
                worker_hash: hash_token(tokens.worker),
                probe,
                jobs_ready: tokio::sync::Notify::new(),
                stopping: std::sync::atomic::AtomicBool::new(false),
                secret_key: tokens.secret_key.clone(),
                videos: video_budget::VideoLedger::default(),
            }),
        }
    }

    pub(crate) fn config(&self) -> &Config {
        &self.inner.config
    }

    pub(crate) fn content(&self) -> &Content {
        &self.inner.content
    }

    /// The write pool (one connection): every write, and reads inside a write's logic.
    pub(crate) fn pool(&self) -> &SqlitePool {
        &self.inner.db.write
    }

    /// The read-only pool: pages, boards and caller lookups, which never wait for a writer.
    pub(crate) fn read_pool(&self) -> &SqlitePool {
        &self.inner.db.read
    }

    pub(crate) fn leaderboard_cache(&self) -> &LeaderboardCache {
        &self.inner.leaderboard
    }

    pub(crate) fn scorer_version(&self) -> String {
        format!("{PLANNING_SCORER}+{}", self.content().dataset_tag())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_format_as_rfc3339_utc() {
        assert_eq!(rfc3339(0), "1970-01-01T00:00:00Z");
        assert_eq!(rfc3339(86_400_000 + 1500), "1970-01-02T00:00:01.5Z");
    }
}
