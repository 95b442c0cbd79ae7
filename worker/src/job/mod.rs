//! Server jobs: a leased `kitchen_r.worker.v1.Job` run to its `EpisodeResult`
//! ([`execute::execute_job`]) and the worker loop that leases, heartbeats and reports
//! ([`run_worker`]), used by `kitchen-r worker` and by the server's in-process slots.
//!
//! `kitchen-r eval --policy http://…` runs its episodes through [`execute::execute_job`] too,
//! with jobs built the way the server builds them, so local and leaderboard numbers agree.

pub mod cores;
mod execute;
mod fetch;
mod lease;
mod live;
pub mod local;
mod path;
mod render;
mod rpc;
pub mod spec;
mod upload;
mod worker;

use std::path::{Path, PathBuf};
use std::time::Duration;

use kitchen_r_sim::{Assets, EpisodeParams, SensorsConfig, SimConfig, SimError};
use serde::{Deserialize, Serialize};

pub use execute::{Executed, JobControl, execute_job, execute_job_recording, execute_job_traced};
pub use lease::run_worker;
pub use live::LiveRos2;
pub use worker::Worker;

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
    /// Simulation cores: episodes stepping their simulators at once; 0 = one per core.
    pub slots: usize,
    /// Episodes held at once, each on its own thread with its own simulator. An episode holds a
    /// core only while it simulates, not while it waits for its policy, so a worker whose
    /// policies are slow keeps more episodes than cores in flight: it leases one more while its
    /// cores were idle more than a tenth of the time. 0 = 8 per slot; at most 512.
    pub max_episodes: usize,
    /// Lease owner name; empty = `hostname-pid`.
    pub worker_id: String,
    /// Address classes a policy endpoint may resolve to besides public ones, as CIDR ranges
    /// (see `kitchen_r_contract::endpoint::CLASS_RANGES`); the default allows loopback only.
    /// The one key for it: `policy.allowed_networks` is refused in a file and ignored in code.
    pub allow_networks: Vec<String>,
    /// Longest long-poll of one Lease call, milliseconds (the server caps it at 30000).
    pub lease_wait_ms: u32,
    /// Offline mode: query the policy at every N-th decision point.
    pub sample_every: usize,
    /// On shutdown: stop leasing, let running episodes finish for up to this many seconds, then
    /// release what is left (the server queues it again at once without using an attempt).
    pub drain_grace_s: u64,
    /// Benchmark content (objects.toml, scenes/, robots/) the simulators load; empty = the
    /// default lookup (`$KITCHEN_R_ASSETS`, `./assets`, the checkout's).
    pub assets: PathBuf,
    /// Transport limits towards policies; the job's deadlines override the deadlines here. Its
    /// `allowed_networks` is not read: `allow_networks` is the one key for that.
    pub policy: RemoteConfig,
}

impl Default for WorkerConfig {
    fn default() -> Self {
        WorkerConfig {
            server: "http://127.0.0.1:50051".into(),
            token: String::new(),
            slots: 0,
            max_episodes: 0,
            worker_id: String::new(),
            allow_networks: vec!["127.0.0.0/8".into(), "::1/128".into()],
            lease_wait_ms: 20_000,
            sample_every: 1,
            drain_grace_s: 30,
            assets: PathBuf::new(),
            policy: RemoteConfig::default(),
        }
    }
}

impl WorkerConfig {
    pub fn load(path: &Path) -> Result<WorkerConfig, WorkerError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| WorkerError::Config(format!("{}: {e}", path.display())))?;
        WorkerConfig::parse(&text).map_err(|e| WorkerError::Config(format!("{}: {e}", path.display())))
    }

    /// A worker.toml's text. `[policy.allowed_networks]` (the transport's own switch) is refused
    /// with a pointer to `allow_networks`: two keys for one setting let one silently replace the
    /// other.
    pub fn parse(text: &str) -> Result<WorkerConfig, String> {
        let table: toml::Table = toml::from_str(text).map_err(|e| e.to_string())?;
        let legacy = (table.get("policy").and_then(|p| p.get("allowed_networks"))).is_some();
        if legacy {
            return Err(
                "`policy.allowed_networks` is not a worker setting: list the networks a policy \
                 endpoint may resolve to in the top-level `allow_networks` (CIDR ranges, e.g. \
                 allow_networks = [\"127.0.0.0/8\", \"10.0.0.0/8\"])"
                    .into(),
            );
        }
        toml::from_str(text).map_err(|e| e.to_string())
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
        if self.slots > 64 {
            return bad("slots", "must be in 0..=64 (0 = one per core)");
        }
        if self.max_episodes > 512 {
            return bad("max_episodes", "must be in 0..=512 (0 = 8 per slot)");
        }
        if self.drain_grace_s > 3600 {
            return bad("drain_grace_s", "must be at most 3600 seconds");
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
        AllowedNetworks::from_cidrs(&self.allow_networks)
            .map_err(|e| WorkerError::Config(format!("`allow_networks`: {e}")))
    }

    /// The transport settings towards policies: `policy` with `allow_networks` as allow-list.
    pub fn remote(&self) -> Result<RemoteConfig, WorkerError> {
        Ok(RemoteConfig {
            allowed_networks: self.allowed()?,
            ..self.policy.clone()
        })
    }

    /// Slots to run: `slots`, or one per core when 0.
    pub fn slot_count(&self) -> usize {
        match self.slots {
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            n => n,
        }
    }

    /// Episodes held at once: `max_episodes`, or 8 per slot when 0; never fewer than the slots.
    pub fn episode_limit(&self) -> usize {
        match self.max_episodes {
            0 => 8 * self.slot_count(),
            n => n.max(self.slot_count()),
        }
    }

    /// The assets directory the simulators load.
    pub fn assets_dir(&self) -> PathBuf {
        if self.assets.as_os_str().is_empty() {
            kitchen_r_core::assets::assets_dir()
        } else {
            self.assets.clone()
        }
    }

    pub(crate) fn drain_grace(&self) -> Duration {
        Duration::from_secs(self.drain_grace_s)
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
    /// A live view online episodes also run with (`eval --foxglove`); the workers have none.
    pub watch: Option<kitchen_r_episode::hooks::WrapHook>,
    /// Live ROS 2 topics of the jobs that ask for them (`EpisodeSpec.live_ros2`, the server's
    /// `[live] ros2`), started at the first.
    pub live: LiveRos2,
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
            watch: None,
            live: LiveRos2::default(),
        })
    }

    /// The context a [`WorkerConfig`] describes: its assets directory, its transport settings
    /// with its allow-list.
    pub fn from_worker_config(cfg: &WorkerConfig) -> Result<JobContext, WorkerError> {
        let dir = cfg.assets_dir();
        let assets = Assets::load(&dir)
            .map_err(|e| WorkerError::Config(format!("`assets` {}: {e}", dir.display())))?;
        Ok(JobContext {
            assets,
            sim: SimConfig::load_default().map_err(JobError::from)?,
            sensors: SensorsConfig::load_default().map_err(JobError::from)?,
            params: EpisodeParams::load_default().map_err(JobError::from)?,
            remote: cfg.remote()?,
            sample_every: cfg.sample_every.max(1),
            watch: None,
            live: LiveRos2::default(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_worker_config_documents_exactly_the_defaults() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/worker.toml");
        assert_eq!(WorkerConfig::load(&file).unwrap(), WorkerConfig::default());
    }

    #[test]
    fn allow_networks_is_the_one_key_for_the_allowed_networks() {
        let cfg = WorkerConfig::parse("allow_networks = [\"127.0.0.0/8\", \"10.0.0.0/8\"]\n").unwrap();
        let remote = cfg.remote().unwrap();
        assert!(remote.allowed_networks.private && remote.allowed_networks.loopback);
        assert!(!remote.allowed_networks.link_local);
        // The transport's own switch used to be silently replaced: it is refused, saying which
        // key to use instead, alone or beside `allow_networks`.
        for text in [
            "[policy.allowed_networks]\nprivate = true\n",
            "allow_networks = [\"10.0.0.0/8\"]\n[policy]\nallowed_networks = { private = true }\n",
        ] {
            let err = WorkerConfig::parse(text).unwrap_err();
            assert!(
                err.contains("policy.allowed_networks") && err.contains("`allow_networks`"),
                "{err}"
            );
        }
        // In code too, the allow-list comes from `allow_networks` only.
        let cfg = WorkerConfig {
            allow_networks: vec!["127.0.0.0/8".into()],
            policy: RemoteConfig {
                allowed_networks: AllowedNetworks::ALL,
                ..RemoteConfig::default()
            },
            ..WorkerConfig::default()
        };
        assert!(!cfg.remote().unwrap().allowed_networks.private);
    }

    #[test]
    fn slots_come_from_the_config_and_zero_means_one_per_core() {
        let cfg = WorkerConfig::parse("slots = 3\n").unwrap();
        assert_eq!(cfg.slot_count(), 3);
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        assert_eq!(WorkerConfig::default().slot_count(), cores);
        let too_many = WorkerConfig {
            token: "t".into(),
            slots: 65,
            ..WorkerConfig::default()
        };
        assert!(too_many.validate().is_err());
    }

    #[test]
    fn the_assets_setting_reaches_the_simulators() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = WorkerConfig {
            assets: dir.path().to_path_buf(),
            ..WorkerConfig::default()
        };
        let err = JobContext::from_worker_config(&cfg).unwrap_err().to_string();
        assert!(err.contains(&dir.path().display().to_string()), "{err}");
        let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets");
        let cfg = WorkerConfig {
            assets: repo,
            ..WorkerConfig::default()
        };
        let ctx = JobContext::from_worker_config(&cfg).unwrap();
        assert!(ctx.assets.scene("kitchen_a").is_ok());
    }
}
