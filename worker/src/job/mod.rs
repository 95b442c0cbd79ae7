//! Server jobs: a leased `kitchen_r.worker.v1.Job` run to its `EpisodeResult`
//! ([`execute::execute_job`]) and the worker loop that leases, heartbeats and reports
//! ([`client::run_worker`]), used by `kitchen-r worker` and by the server's in-process slots.
//!
//! `kitchen-r eval --policy http://…` runs its episodes through [`execute::execute_job`] too,
//! with jobs built the way the server builds them, so local and leaderboard numbers agree.

pub mod client;
mod execute;
pub mod local;
pub mod spec;

use std::path::Path;
use std::time::Duration;

use kitchen_r_sim::{Assets, EpisodeParams, SensorsConfig, SimConfig, SimError};
use serde::{Deserialize, Serialize};

pub use client::run_worker;
pub use execute::{JobControl, execute_job};

use kitchen_r_contract::{AllowedNetworks, RemoteConfig};
use kitchen_r_episode::runner::RunError;

/// Why a job could not be run; every variant is a platform error (retried, never charged).
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error("job: {0}")]
    Spec(String),
    #[error("worker set-up: {0}")]
    Setup(String),
    #[error("simulator: {0}")]
    Sim(#[from] SimError),
    #[error("{0}")]
    Run(#[from] RunError),
}

/// Why the worker loop stopped (transient failures never stop it).
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    #[error("worker config: {0}")]
    Config(String),
    #[error(transparent)]
    Job(#[from] JobError),
    #[error("the server refused this worker: {0} (check the worker token)")]
    Refused(String),
}

/// `kitchen-r worker` settings (TOML file `configs/worker.toml` when present, then flags).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WorkerConfig {
    /// The server's gRPC address, `http://HOST:PORT` (or https).
    pub server: String,
    /// Worker token, sent as `authorization: Bearer <token>`.
    pub token: String,
    /// Episodes run at once (each on its own thread with its own simulator).
    pub slots: usize,
    /// Lease owner name; empty = `hostname-pid`.
    pub worker_id: String,
    /// Address classes a policy endpoint may resolve to besides public ones, as CIDR ranges
    /// (see `kitchen_r_contract::endpoint::CLASS_RANGES`); the default allows loopback only.
    pub allow_networks: Vec<String>,
    /// Longest long-poll of one Lease call, milliseconds (the server caps it at 30000).
    pub lease_wait_ms: u32,
    /// Offline mode: query the policy at every N-th decision point.
    pub sample_every: usize,
    /// Transport limits towards policies; the job's deadlines override the deadlines here.
    pub policy: RemoteConfig,
}

impl Default for WorkerConfig {
    fn default() -> Self {
        WorkerConfig {
            server: "http://127.0.0.1:50051".into(),
            token: String::new(),
            slots: 1,
            worker_id: String::new(),
            allow_networks: vec!["127.0.0.0/8".into(), "::1/128".into()],
            lease_wait_ms: 20_000,
            sample_every: 1,
            policy: RemoteConfig::default(),
        }
    }
}

impl WorkerConfig {
    pub fn load(path: &Path) -> Result<WorkerConfig, WorkerError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| WorkerError::Config(format!("{}: {e}", path.display())))?;
        toml::from_str(&text).map_err(|e| WorkerError::Config(format!("{}: {e}", path.display())))
    }

    /// `configs/worker.toml` when present, else the defaults.
    pub fn load_default() -> Result<WorkerConfig, WorkerError> {
        let path = kitchen_r_sim::config::configs_dir().join("worker.toml");
        if path.is_file() {
            WorkerConfig::load(&path)
        } else {
            Ok(WorkerConfig::default())
        }
    }

    /// Check every value; the message names the key.
    pub(crate) fn validate(&self) -> Result<(), WorkerError> {
        let bad = |k: &str, m: &str| Err(WorkerError::Config(format!("`{k}`: {m}")));
        if !(self.server.starts_with("http://") || self.server.starts_with("https://")) {
            return bad("server", "must be http://HOST:PORT or https://HOST:PORT");
        }
        if self.token.is_empty() {
            return bad(
                "token",
                "a worker token is required (--token or KITCHEN_R_WORKER_TOKEN)",
            );
        }
        if !(1..=64).contains(&self.slots) {
            return bad("slots", "must be in 1..=64");
        }
        if !(1..=30_000).contains(&self.lease_wait_ms) {
            return bad("lease_wait_ms", "must be in 1..=30000");
        }
        if self.sample_every == 0 {
            return bad("sample_every", "must be at least 1");
        }
        self.allowed().map(drop)
    }

    pub(crate) fn allowed(&self) -> Result<AllowedNetworks, WorkerError> {
        AllowedNetworks::from_cidrs(&self.allow_networks).map_err(WorkerError::Config)
    }

    /// The configured id, or `hostname-pid`.
    pub(crate) fn worker_id(&self) -> String {
        if !self.worker_id.is_empty() {
            return self.worker_id.clone();
        }
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .map(|h| h.trim().to_string())
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "worker".into());
        format!("{host}-{}", std::process::id())
    }

    pub(crate) fn lease_wait(&self) -> Duration {
        Duration::from_millis(u64::from(self.lease_wait_ms))
    }
}

/// Everything a job needs that does not change between jobs; loaded once per worker process.
#[derive(Debug, Clone)]
pub struct JobContext {
    pub assets: Assets,
    pub sim: SimConfig,
    pub sensors: SensorsConfig,
    pub params: EpisodeParams,
    /// Transport limits and the endpoint allow-list.
    pub remote: RemoteConfig,
    /// Offline mode: query the policy at every N-th decision point.
    pub sample_every: usize,
}

impl JobContext {
    /// The default assets and configs, and `remote` with `allow` as its allow-list. No dataset:
    /// every job carries its episode.
    pub fn load(
        remote: RemoteConfig,
        allow: AllowedNetworks,
        sample_every: usize,
    ) -> Result<JobContext, JobError> {
        Ok(JobContext {
            assets: Assets::load_default()?,
            sim: SimConfig::load_default()?,
            sensors: SensorsConfig::load_default()?,
            params: EpisodeParams::load_default()?,
            remote: RemoteConfig {
                allowed_networks: allow,
                ..remote
            },
            sample_every: sample_every.max(1),
        })
    }

    /// The context a [`WorkerConfig`] describes.
    pub(crate) fn from_worker_config(cfg: &WorkerConfig) -> Result<JobContext, WorkerError> {
        Ok(JobContext::load(
            cfg.policy.clone(),
            cfg.allowed()?,
            cfg.sample_every,
        )?)
    }
}
