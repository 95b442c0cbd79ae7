//! Server configuration, layered: built-in defaults → a TOML file (`configs/server.toml` or
//! `--config FILE`) → `KITCHEN_R_*` environment variables → command-line flags (applied by the
//! binary). [`Config::validate`] runs once at start so a bad value stops the server before it
//! listens, with a message naming the key.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use figment::Figment;
use figment::providers::{Env, Format, Serialized, Toml};
use kitchen_r_core::GraspMode;
use serde::{Deserialize, Serialize};

mod leaderboard;
mod live;
mod secrets;
mod sessions;
mod video;
pub(crate) use leaderboard::LeaderboardConfig;
pub(crate) use live::LiveConfig;
pub(crate) use secrets::SecretsConfig;
pub(crate) use sessions::SessionConfig;
pub(crate) use video::{Prerender, VideoConfig};

/// The directory holding the SQLite database file of URL `db`, where files kept beside it
/// (videos, the secret key) go; `None` for an in-memory database, which has no directory.
fn beside_database(db: &str) -> Option<PathBuf> {
    let path = db
        .strip_prefix("sqlite://")
        .or_else(|| db.strip_prefix("sqlite:"))?;
    let path = path.split('?').next().unwrap_or_default();
    let in_memory = path.contains(":memory:") || path.starts_with("file:") && path.contains("mode=memory");
    if path.is_empty() || in_memory {
        return None;
    }
    Some(Path::new(path).parent().map(PathBuf::from).unwrap_or_default())
}

/// Environment variables read into the configuration (`KITCHEN_R_<KEY>`). Listed explicitly so
/// the client-side variables (`KITCHEN_R_SERVER`, `KITCHEN_R_TOKEN`) are not mistaken for keys.
const ENV_KEYS: [&str; 13] = [
    "http",
    "grpc",
    "db",
    "workers",
    "assets",
    "test_set",
    "contest",
    "admin_token",
    "worker_token",
    "max_body_bytes",
    "request_timeout_ms",
    "metrics",
    "strict",
];

/// Nested keys also read from the environment, `KITCHEN_R_<SECTION>_<KEY>`: the storage budgets,
/// so a deployment sizes them to its volume without a config file of its own (deploy/).
const ENV_NESTED: [(&str, &str); 2] = [("video", "team_max_bytes"), ("video", "total_max_bytes")];

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// HTTP listen address.
    pub http: String,
    /// gRPC listen address.
    pub grpc: String,
    /// SQLite URL; the file and its directory are created if missing.
    pub db: String,
    /// In-process simulation slots for policy evaluation; unset means one per CPU core, 0 means
    /// none (every episode waits for a standalone `kitchen-r worker`).
    pub workers: Option<usize>,
    /// Benchmark content (scenes, catalogue, `dataset/`); empty means the default lookup of
    /// `kitchen_r_core::assets::assets_dir()`.
    pub assets: PathBuf,
    /// The test split to serve and score: a directory written by `kitchen-r dataset generate`
    /// (outside the repository, for a contest); empty means the repository's public sample
    /// (`<assets>/dataset`), whose answers are public.
    pub test_set: PathBuf,
    /// Contest mode: refuse to start unless the test set is private (generated with private
    /// phrasings, its seed not recorded).
    pub contest: bool,
    /// Organiser token; empty means generate one at start and print it once.
    pub admin_token: String,
    /// Token simulation workers present on the gRPC `Worker` service; empty means generate one
    /// at start (in-process workers get it from [`crate::Server::worker_token`]).
    pub worker_token: String,
    /// Largest accepted request body, bytes, on every route that reads one (a plan file, a
    /// registration, an organiser request); past it, 413 `body_too_large`.
    pub max_body_bytes: usize,
    /// Budget of one HTTP or gRPC request, milliseconds; past it the request is abandoned and
    /// answered 503 / UNAVAILABLE (code `timeout`). Calls that wait by design get more on top:
    /// policy registration `policy.startup_deadline_ms` (it probes the endpoint), a worker's
    /// long-polling Lease its longest wait (30 s); the organiser's rescore has no budget.
    pub request_timeout_ms: u64,
    /// Serve `GET /metrics` (Prometheus text format, no token: it holds no team data) and
    /// record the series it shows.
    pub metrics: bool,
    /// Refuse to start on what is otherwise a start-up warning: storage budgets (`[video]
    /// total_max_bytes`) that the free space of their volume cannot hold.
    pub strict: bool,
    pub plans: PlanLimits,
    pub quota: Quota,
    pub db_pool: DbPool,
    pub control: ControlConfig,
    pub policy: PolicyConfig,
    pub video: VideoConfig,
    pub live: LiveConfig,
    pub sessions: SessionConfig,
    pub secrets: SecretsConfig,
    pub leaderboard: LeaderboardConfig,
}

/// How requests share the database (`[db_pool]`). Writes have one connection of their own
/// (SQLite has one writer), so an upload never waits behind leaderboard readers; readers share
/// `read_connections` read-only ones. A request that cannot get a connection within its wait
/// is answered 503 `busy` with `Retry-After`, instead of queueing for seconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DbPool {
    /// Read-only connections for pages, leaderboards and token lookups.
    pub read_connections: u32,
    /// Longest wait for the write connection (and for SQLite's write lock), milliseconds.
    pub write_wait_ms: u64,
    /// Longest wait for a read connection, milliseconds.
    pub read_wait_ms: u64,
}

impl Default for DbPool {
    fn default() -> Self {
        DbPool {
            read_connections: 8,
            write_wait_ms: 2_000,
            read_wait_ms: 2_000,
        }
    }
}

/// Limits on an uploaded plan file, beyond the body size.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlanLimits {
    /// Most characters in one step; canonical steps are under 40.
    pub max_step_chars: usize,
    /// Most steps in one plan; ground-truth plans have 4 to 8.
    pub max_steps: usize,
}

/// What one team may submit (`[quota]`). The defaults bound every split, so no team can fill the
/// disk: a team stores at most `*_per_day` submissions of at most `max_body_bytes` per split
/// and day, and reaches that no faster than `per_minute`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields, default)]
pub struct Quota {
    /// Submissions (plan files and policy registrations) per team, per split, per UTC day;
    /// 0 means unlimited.
    pub dev_per_day: u32,
    pub test_per_day: u32,
    /// Upload attempts (plan files and policy registrations, accepted or not) per team, per
    /// split, per minute, as a burst that refills at this rate; 0 means unlimited. Held in the
    /// server's memory (see `service::limits`).
    pub per_minute: u32,
    /// Policy runs of one team evaluating at the same time; 0 means unlimited.
    pub concurrent_runs: u32,
}

/// How policy runs are cut into episode jobs and how the job queue behaves (`[control]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControlConfig {
    /// Queue an offline (MSE) episode beside each online one.
    pub offline_mse: bool,
    /// Evaluate only the first N dev instructions (0 = all); the test split always runs whole.
    pub dev_episodes: u32,
    /// Run seed handed to workers, which derive each instruction's seed from it.
    pub seed: u64,
    /// Simulated seconds per task.
    pub task_time_limit_s: f64,
    /// Actions executed from each 16-action chunk before the policy is asked again, for a
    /// policy that does not choose its own count.
    pub actions_executed_per_chunk: u32,
    /// The smallest count a policy may choose in GetSpec (contract v1.1; the largest is 16).
    /// Each query renders its frames, so a small count costs the organiser more simulation.
    pub min_actions_executed_per_chunk: u32,
    /// After a failed task, move robot and objects to the expert's state for the next one.
    pub teleport_on_failure: bool,
    /// Execute at most this many plan steps per episode; 0 = all.
    pub max_plan_steps: u32,
    /// Lease length granted by Lease and by each Heartbeat, seconds.
    pub lease_s: u64,
    /// How often expired leases are requeued, seconds.
    pub reaper_interval_s: u64,
    /// Leases a job gets before its episode is recorded as failed.
    pub max_attempts: u32,
    /// Most jobs of one team leased at once, over all its runs; 0 = unlimited. Leasing shares
    /// capacity fairly whatever this is (fewest in flight first, by team then run).
    pub max_in_flight_per_team: u32,
    /// At shutdown the in-process slots stop leasing, finish their running episodes for up to
    /// this long, then release what is left (queued again at once, no attempt used), seconds.
    pub drain_grace_s: u64,
    /// Episodes the in-process slots hold at once; each holds a slot only while it simulates,
    /// not while it waits for its policy (the worker's `max_episodes`). 0 = 8 per slot.
    pub max_episodes: usize,
    /// Run the privileged-information track: a policy may ask in GetSpec for privileged
    /// observations (robot pose in the scene frame, the current goal, key objects; on the test
    /// split only what the sub-task names) and is then ranked on the privileged boards. Off, a
    /// registration that asks is refused, naming this key.
    pub privileged_track: bool,
    /// The grasp mode every policy episode runs in (docs/twin/robot.md): `abstract` (the default)
    /// or
    /// `physical`. Sent with every job (it overrides the workers' `[grasp] mode`), stored with
    /// each run and shown with every control score; boards rank the runs of one mode together.
    pub grasp: GraspMode,
}

/// Calling participants' policies (`[policy]`): deadlines and chunk check tolerances sent to
/// workers with every job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyConfig {
    /// Deadline of one Reset or Act call, milliseconds.
    pub call_deadline_ms: u32,
    /// Time an endpoint has to become healthy, milliseconds.
    pub startup_deadline_ms: u32,
    /// Wall-clock budget of one whole episode, milliseconds.
    pub episode_budget_ms: u32,
    /// Abort an episode after this many successive call timeouts.
    pub max_successive_timeouts: u32,
    /// Networks (CIDR) a policy endpoint may resolve to besides public addresses. Handed to the
    /// registration probe, which owns the parsing and the check.
    pub allow_networks: Vec<String>,
    /// Largest |‖q‖ − 1| of a chunk's quaternion that workers normalise (and count as a
    /// warning) instead of failing the task; 0 to 1.
    pub quat_norm_tolerance: f64,
    /// Largest distance of a gripper value outside [0, 1] that workers clamp (and count)
    /// instead of failing the task; 0 to 1.
    pub gripper_margin: f64,
    /// Batched decisions of `serve`'s in-process workers (a remote worker reads its own
    /// configs/worker.toml): the most decisions one ActBatch call carries; 0 or 1 = Acts only.
    pub max_batch: u32,
    /// Batched decisions of `serve`'s in-process workers: the gather window, milliseconds.
    pub batch_gather_ms: f64,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            http: "127.0.0.1:8080".into(),
            grpc: "127.0.0.1:50051".into(),
            db: "sqlite://data/kitchen-r.db".into(),
            workers: None,
            assets: PathBuf::new(),
            test_set: PathBuf::new(),
            contest: false,
            strict: false,
            admin_token: String::new(),
            worker_token: String::new(),
            max_body_bytes: 4 << 20,
            request_timeout_ms: 30_000,
            metrics: true,
            plans: PlanLimits::default(),
            quota: Quota::default(),
            db_pool: DbPool::default(),
            control: ControlConfig::default(),
            policy: PolicyConfig::default(),
            video: VideoConfig::default(),
            live: LiveConfig::default(),
            sessions: SessionConfig::default(),
            secrets: SecretsConfig::default(),
            leaderboard: LeaderboardConfig::default(),
        }
    }
}

impl Default for PlanLimits {
    fn default() -> Self {
        PlanLimits {
            max_step_chars: 200,
            max_steps: 64,
        }
    }
}

impl PlanLimits {
    /// No limits: used to rescore stored files, which were accepted under the limits of their day.
    pub const UNLIMITED: PlanLimits = PlanLimits {
        max_step_chars: usize::MAX,
        max_steps: usize::MAX,
    };
}

impl Default for Quota {
    fn default() -> Self {
        Quota {
            dev_per_day: 200,
            test_per_day: 5,
            per_minute: 20,
            concurrent_runs: 2,
        }
    }
}

impl Default for ControlConfig {
    fn default() -> Self {
        ControlConfig {
            offline_mse: true,
            dev_episodes: 0,
            seed: 0,
            task_time_limit_s: 120.0,
            actions_executed_per_chunk: 8,
            min_actions_executed_per_chunk: 1,
            teleport_on_failure: true,
            max_plan_steps: 0,
            lease_s: 60,
            reaper_interval_s: 5,
            max_attempts: 3,
            max_in_flight_per_team: 0,
            drain_grace_s: 30,
            max_episodes: 0,
            privileged_track: false,
            grasp: GraspMode::Abstract,
        }
    }
}

impl Default for PolicyConfig {
    fn default() -> Self {
        PolicyConfig {
            call_deadline_ms: 10_000,
            startup_deadline_ms: 30_000,
            episode_budget_ms: 600_000,
            max_successive_timeouts: 3,
            allow_networks: vec!["127.0.0.0/8".into(), "::1/128".into()],
            quat_norm_tolerance: 0.1,
            gripper_margin: 0.05,
            max_batch: 64,
            batch_gather_ms: 2.0,
        }
    }
}

/// A configuration that cannot be loaded or is not valid.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("configuration: {0}")]
    Load(#[from] Box<figment::Error>),
    #[error("configuration key `{key}`: {message}")]
    Invalid { key: &'static str, message: String },
}

impl Config {
    /// Defaults, then `file` (when given it must exist; otherwise `configs/server.toml` is read
    /// if present), then `KITCHEN_R_*` variables.
    pub fn load(file: Option<&Path>) -> Result<Config, ConfigError> {
        let mut fig = Figment::from(Serialized::defaults(Config::default()));
        match file {
            Some(f) if !f.is_file() => {
                return Err(ConfigError::Invalid {
                    key: "--config",
                    message: format!("{} is not a file", f.display()),
                });
            }
            Some(f) => fig = fig.merge(Toml::file(f)),
            None => fig = fig.merge(Toml::file("configs/server.toml")),
        }
        let env = Env::prefixed("KITCHEN_R_").only(&ENV_KEYS);
        let nested: Vec<String> = ENV_NESTED.iter().map(|(s, k)| format!("{s}_{k}")).collect();
        let nested = Env::prefixed("KITCHEN_R_")
            .filter(move |k| nested.iter().any(|n| k.as_str().eq_ignore_ascii_case(n)))
            .map(|k| {
                match ENV_NESTED
                    .iter()
                    .find(|(s, key)| k.as_str().eq_ignore_ascii_case(&format!("{s}_{key}")))
                {
                    Some((s, key)) => format!("{s}.{key}").into(),
                    None => k.into(),
                }
            });
        fig.merge(env)
            .merge(nested)
            .extract()
            .map_err(|e| ConfigError::Load(Box::new(e)))
    }

    /// Check every value; the error names the key to fix.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let invalid = |key, message: String| Err(ConfigError::Invalid { key, message });
        if let Err(e) = self.http.parse::<SocketAddr>() {
            return invalid("http", format!("{:?} is not an address: {e}", self.http));
        }
        if let Err(e) = self.grpc.parse::<SocketAddr>() {
            return invalid("grpc", format!("{:?} is not an address: {e}", self.grpc));
        }
        if !self.db.starts_with("sqlite:") {
            return invalid("db", format!("{:?} is not a sqlite: URL", self.db));
        }
        if !(1024..=(256 << 20)).contains(&self.max_body_bytes) {
            return invalid("max_body_bytes", "must be between 1 KiB and 256 MiB".into());
        }
        if !(100..=3_600_000).contains(&self.request_timeout_ms) {
            return invalid(
                "request_timeout_ms",
                "must be between 100 ms and 3600000 ms (one hour)".into(),
            );
        }
        let pool = self.db_pool;
        if !(1..=64).contains(&pool.read_connections) {
            return invalid("db_pool.read_connections", "must be between 1 and 64".into());
        }
        if !(10..=60_000).contains(&pool.write_wait_ms) || !(10..=60_000).contains(&pool.read_wait_ms) {
            return invalid(
                "db_pool",
                "write_wait_ms and read_wait_ms must be between 10 and 60000".into(),
            );
        }
        if self.plans.max_step_chars == 0 || self.plans.max_steps == 0 {
            return invalid("plans", "max_step_chars and max_steps must be at least 1".into());
        }
        if !self.admin_token.is_empty() && self.admin_token.len() < 16 {
            return invalid("admin_token", "must be at least 16 characters".into());
        }
        if !self.worker_token.is_empty() && self.worker_token.len() < 16 {
            return invalid("worker_token", "must be at least 16 characters".into());
        }
        self.video.validate()?;
        self.sessions.validate()?;
        self.validate_control()
    }

    fn validate_control(&self) -> Result<(), ConfigError> {
        let invalid = |key, message: &str| {
            Err(ConfigError::Invalid {
                key,
                message: message.into(),
            })
        };
        let c = &self.control;
        if !(c.task_time_limit_s.is_finite() && c.task_time_limit_s > 0.0) {
            return invalid(
                "control.task_time_limit_s",
                "must be a positive number of seconds",
            );
        }
        if !(1..=16).contains(&c.actions_executed_per_chunk) {
            return invalid("control.actions_executed_per_chunk", "must be between 1 and 16");
        }
        if !(1..=c.actions_executed_per_chunk).contains(&c.min_actions_executed_per_chunk) {
            return invalid(
                "control.min_actions_executed_per_chunk",
                "must be between 1 and control.actions_executed_per_chunk (the default must be allowed)",
            );
        }
        if c.lease_s == 0 || c.reaper_interval_s == 0 {
            return invalid(
                "control.lease_s",
                "lease_s and reaper_interval_s must be at least 1",
            );
        }
        if c.max_attempts == 0 {
            return invalid("control.max_attempts", "must be at least 1");
        }
        if c.drain_grace_s > 3600 {
            return invalid("control.drain_grace_s", "must be at most 3600 seconds");
        }
        if c.max_episodes > 512 {
            return invalid("control.max_episodes", "must be in 0..=512 (0 = 8 per slot)");
        }
        let p = &self.policy;
        if p.call_deadline_ms == 0 || p.startup_deadline_ms == 0 || p.episode_budget_ms == 0 {
            return invalid(
                "policy",
                "call_deadline_ms, startup_deadline_ms and episode_budget_ms must be at least 1",
            );
        }
        if p.max_successive_timeouts == 0 {
            return invalid("policy.max_successive_timeouts", "must be at least 1");
        }
        if !(0.0..=1.0).contains(&p.quat_norm_tolerance) {
            return invalid("policy.quat_norm_tolerance", "must be between 0 and 1");
        }
        if !(0.0..=1000.0).contains(&p.batch_gather_ms) {
            return invalid(
                "policy.batch_gather_ms",
                "must be between 0 and 1000 milliseconds",
            );
        }
        if !(0.0..=1.0).contains(&p.gripper_margin) {
            return invalid("policy.gripper_margin", "must be between 0 and 1");
        }
        Ok(())
    }

    /// The budget of one HTTP or gRPC request (`request_timeout_ms`).
    pub fn request_timeout(&self) -> Duration {
        Duration::from_millis(self.request_timeout_ms)
    }

    /// The budget of a policy registration: a request's plus the endpoint probe's
    /// (`policy.startup_deadline_ms`), so a slow but healthy endpoint is not cut off.
    pub fn registration_timeout(&self) -> Duration {
        self.request_timeout() + Duration::from_millis(self.policy.startup_deadline_ms.into())
    }

    /// The private test set directory, if one is configured.
    pub fn test_set_dir(&self) -> Option<&Path> {
        (!self.test_set.as_os_str().is_empty()).then_some(self.test_set.as_path())
    }

    /// The assets directory to use.
    pub fn assets_dir(&self) -> PathBuf {
        if self.assets.as_os_str().is_empty() {
            kitchen_r_core::assets::assets_dir()
        } else {
            self.assets.clone()
        }
    }

    /// In-process simulation slots: `workers`, or the number of cores when unset.
    pub fn worker_slots(&self) -> usize {
        self.workers
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_match_the_documented_ones() {
        let c = Config::default();
        c.validate().unwrap();
        assert_eq!(c.quota.test_per_day, 5);
        // Every split is bounded by default: an unlimited dev split filled the disk.
        assert_eq!((c.quota.dev_per_day, c.quota.per_minute), (200, 20));
    }

    #[test]
    fn the_shipped_config_file_documents_exactly_the_defaults() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/server.toml");
        // The file alone, without KITCHEN_R_* variables the environment may set.
        let c: Config = Figment::from(Serialized::defaults(Config::default()))
            .merge(Toml::file(&file))
            .extract()
            .unwrap();
        assert_eq!(c, Config::default());
        assert_eq!(c.quota.concurrent_runs, 2);
        assert_eq!(c.request_timeout_ms, 30_000);
        assert!(c.control.offline_mse);
        assert_eq!(c.policy.allow_networks, ["127.0.0.0/8", "::1/128"]);
    }

    #[test]
    fn control_values_are_checked() {
        let mut c = Config::default();
        c.control.actions_executed_per_chunk = 17;
        assert!(matches!(
            c.validate(),
            Err(ConfigError::Invalid {
                key: "control.actions_executed_per_chunk",
                ..
            })
        ));
        let mut c = Config::default();
        c.control.max_attempts = 0;
        assert!(c.validate().is_err());
        let mut c = Config::default();
        c.control.min_actions_executed_per_chunk = 9;
        assert!(matches!(
            c.validate(),
            Err(ConfigError::Invalid {
                key: "control.min_actions_executed_per_chunk",
                ..
            })
        ));
        let mut c = Config::default();
        c.policy.gripper_margin = f64::NAN;
        assert!(c.validate().is_err());
        let c = Config {
            worker_token: "short".into(),
            ..Config::default()
        };
        assert!(c.validate().is_err());
    }

    #[test]
    fn the_grasp_mode_is_read_and_an_unknown_one_is_refused_naming_the_choices() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("s.toml");
        std::fs::write(&f, "[control]\ngrasp = \"physical\"\n").unwrap();
        assert_eq!(Config::load(Some(&f)).unwrap().control.grasp, GraspMode::Physical);
        std::fs::write(&f, "[control]\ngrasp = \"magic\"\n").unwrap();
        let err = Config::load(Some(&f)).unwrap_err().to_string();
        for needed in ["control.grasp", "magic", "abstract", "physical"] {
            assert!(err.contains(needed), "{needed:?} missing from: {err}");
        }
    }

    #[test]
    fn the_request_timeout_is_checked() {
        for bad in [0, 99, 3_600_001] {
            let c = Config {
                request_timeout_ms: bad,
                ..Config::default()
            };
            assert!(
                matches!(
                    c.validate(),
                    Err(ConfigError::Invalid {
                        key: "request_timeout_ms",
                        ..
                    })
                ),
                "{bad}"
            );
        }
    }

    #[test]
    fn file_then_env_override_defaults() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("s.toml");
        std::fs::write(&f, "http = \"127.0.0.1:9000\"\n[quota]\ntest_per_day = 2\n").unwrap();
        let c = Config::load(Some(&f)).unwrap();
        assert_eq!(c.http, "127.0.0.1:9000");
        assert_eq!(c.quota.test_per_day, 2);
        assert_eq!(c.grpc, "127.0.0.1:50051");
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("s.toml");
        std::fs::write(&f, "htp = \"x\"\n").unwrap();
        assert!(Config::load(Some(&f)).is_err());
        let c = Config {
            http: "nowhere".into(),
            ..Config::default()
        };
        assert!(matches!(
            c.validate(),
            Err(ConfigError::Invalid { key: "http", .. })
        ));
    }
}
