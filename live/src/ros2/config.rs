//! `configs/live.toml` `[ros2]`: the DDS domain, where discovery may go, and the QoS of the
//! published topics. Defaults → the file → `ROS_DOMAIN_ID` (as every ROS 2 node reads it).

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::Ros2Error;

/// The highest domain id whose RTPS ports (7400 + 250 × id + …) fit in 16 bits.
pub const MAX_DOMAIN_ID: u16 = 232;

/// The environment variable ROS 2 reads its domain id from; it overrides the file.
pub const DOMAIN_ENV: &str = "ROS_DOMAIN_ID";

/// Which network interfaces DDS discovery and data use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Network {
    /// 127.0.0.1 only: discovery is sent by unicast to the well-known ports of this host's
    /// participants, and no multicast leaves the machine. A subscriber on the same host must
    /// also allow loopback (ROS 2: `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, or Cyclone DDS
    /// with `Peers` 127.0.0.1).
    #[default]
    Loopback,
    /// Every interface, with multicast discovery (239.255.0.1) as a stock ROS 2 node does:
    /// other hosts on the network see the topics.
    All,
}

/// DDS RELIABILITY.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Reliability {
    /// Matches both reliable and best-effort subscribers (a ROS 2 node's default is reliable).
    /// A writer never waits for a slow subscriber: a full send window drops the sample.
    #[default]
    Reliable,
    BestEffort,
}

/// DDS DURABILITY.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Durability {
    #[default]
    Volatile,
    /// A late subscriber (asking for transient-local) gets the last `depth` samples.
    TransientLocal,
}

/// `[ros2]` of `configs/live.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Ros2Config {
    /// The DDS domain (`ROS_DOMAIN_ID`), 0..=232.
    pub domain_id: u16,
    pub network: Network,
    /// QoS of every topic but `/tf_static`, which is reliable and transient-local with depth 1
    /// as tf2 expects of it.
    pub reliability: Reliability,
    pub durability: Durability,
    /// KEEP_LAST history depth, 1..=1000.
    pub depth: u32,
}

impl Default for Ros2Config {
    fn default() -> Self {
        Ros2Config {
            domain_id: 0,
            network: Network::Loopback,
            reliability: Reliability::Reliable,
            durability: Durability::Volatile,
            depth: 10,
        }
    }
}

#[derive(Debug, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
struct LiveToml {
    ros2: Ros2Config,
}

impl Ros2Config {
    /// `[ros2]` of the file at `path`, then `ROS_DOMAIN_ID`, validated.
    pub fn load(path: &Path) -> Result<Ros2Config, Ros2Error> {
        let bad = |m: String| Ros2Error::Config(format!("{}: {m}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
        let file: LiveToml = toml::from_str(&text).map_err(|e| bad(e.to_string()))?;
        file.ros2.with_env()?.validated().map_err(bad)
    }

    /// `configs/live.toml` when present, else the defaults; then `ROS_DOMAIN_ID`.
    pub fn load_default(configs: &Path) -> Result<Ros2Config, Ros2Error> {
        let path = configs.join("live.toml");
        if path.is_file() {
            return Ros2Config::load(&path);
        }
        let c = Ros2Config::default().with_env()?;
        c.validated().map_err(Ros2Error::Config)
    }

    fn with_env(mut self) -> Result<Ros2Config, Ros2Error> {
        if let Ok(v) = std::env::var(DOMAIN_ENV)
            && !v.trim().is_empty()
        {
            self.domain_id = v.trim().parse().map_err(|_| {
                Ros2Error::Config(format!("{DOMAIN_ENV}={v:?}: a domain id 0..={MAX_DOMAIN_ID}"))
            })?;
        }
        Ok(self)
    }

    fn validated(self) -> Result<Ros2Config, String> {
        if self.domain_id > MAX_DOMAIN_ID {
            return Err(format!(
                "ros2.domain_id {}: at most {MAX_DOMAIN_ID}",
                self.domain_id
            ));
        }
        if !(1..=1000).contains(&self.depth) {
            return Err(format!("ros2.depth {}: 1..=1000", self.depth));
        }
        Ok(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_file_is_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/live.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let file: LiveToml = toml::from_str(&text).unwrap();
        assert_eq!(file.ros2, Ros2Config::default());
    }

    #[test]
    fn bad_values_are_refused() {
        let parse = |s: &str| toml::from_str::<LiveToml>(s).map(|f| f.ros2.validated());
        assert!(parse("[ros2]\ndomain_id = 233\n").unwrap().is_err());
        assert!(parse("[ros2]\ndepth = 0\n").unwrap().is_err());
        assert!(parse("[ros2]\nreliability = \"sometimes\"\n").is_err());
        assert!(
            parse("[ros2]\nnetwork = \"all\"\ndurability = \"transient_local\"\n")
                .unwrap()
                .is_ok()
        );
    }
}
