//! Server configuration, layered: built-in defaults → a TOML file (`configs/server.toml` or
//! `--config FILE`) → `KITCHEN_R_*` environment variables → command-line flags (applied by the
//! binary). [`Config::validate`] runs once at start so a bad value stops the server before it
//! listens, with a message naming the key.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use figment::Figment;
use figment::providers::{Env, Format, Serialized, Toml};
use serde::{Deserialize, Serialize};

/// Environment variables read into the configuration (`KITCHEN_R_<KEY>`). Listed explicitly so
/// the client-side variables (`KITCHEN_R_SERVER`, `KITCHEN_R_TOKEN`) are not mistaken for keys.
const ENV_KEYS: [&str; 7] = [
    "http",
    "grpc",
    "db",
    "workers",
    "assets",
    "admin_token",
    "max_body_bytes",
];

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// HTTP listen address.
    pub http: String,
    /// gRPC listen address.
    pub grpc: String,
    /// SQLite URL; the file and its directory are created if missing.
    pub db: String,
    /// In-process simulation slots for policy evaluation; 0 means one per CPU core.
    pub workers: usize,
    /// Benchmark content (scenes, catalogue, `dataset/`); empty means the default lookup of
    /// `kitchen_r_core::assets::assets_dir()`.
    pub assets: PathBuf,
    /// Organiser token; empty means generate one at start and print it once.
    pub admin_token: String,
    /// Largest accepted request body (a plan file), bytes.
    pub max_body_bytes: usize,
    pub plans: PlanLimits,
    pub quota: Quota,
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

/// Submissions allowed per team, per split, per UTC day; 0 means unlimited.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Quota {
    pub dev_per_day: u32,
    pub test_per_day: u32,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            http: "127.0.0.1:8080".into(),
            grpc: "127.0.0.1:50051".into(),
            db: "sqlite://data/kitchen-r.db".into(),
            workers: 0,
            assets: PathBuf::new(),
            admin_token: String::new(),
            max_body_bytes: 4 << 20,
            plans: PlanLimits::default(),
            quota: Quota::default(),
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
            dev_per_day: 0,
            test_per_day: 5,
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
        fig.merge(env)
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
        if self.plans.max_step_chars == 0 || self.plans.max_steps == 0 {
            return invalid("plans", "max_step_chars and max_steps must be at least 1".into());
        }
        if !self.admin_token.is_empty() && self.admin_token.len() < 16 {
            return invalid("admin_token", "must be at least 16 characters".into());
        }
        Ok(())
    }

    /// The assets directory to use.
    pub fn assets_dir(&self) -> PathBuf {
        if self.assets.as_os_str().is_empty() {
            kitchen_r_core::assets::assets_dir()
        } else {
            self.assets.clone()
        }
    }

    /// Simulation slots: `workers`, or the number of cores when 0.
    pub fn worker_slots(&self) -> usize {
        if self.workers > 0 {
            self.workers
        } else {
            std::thread::available_parallelism().map_or(1, |n| n.get())
        }
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
        assert_eq!(c.quota.dev_per_day, 0);
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
