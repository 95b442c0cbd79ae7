//! `configs/collect.toml`: the Monitoring Module's thresholds for trajectory collection.

use std::collections::BTreeMap;
use std::path::Path;

use kitchen_r_sim::config::MonitorConfig;
use serde::{Deserialize, Serialize};

use super::CollectError;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CollectConfig {
    /// Per-action time limits and the end-of-action checks (the sim's monitor keys).
    pub monitors: MonitorConfig,
    pub rates: RateConfig,
    /// Apply the paper's randomisation to every episode built from a dataset instruction
    /// (`kitchen_r_sim::randomise`, each aspect as switched in `configs/episodes.toml`
    /// `[randomise]`); `randomize_style`, its former name, is still read.
    #[serde(alias = "randomize_style")]
    pub randomise: bool,
}

/// Recording-rate minimums per topic, over a sliding window of sim time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RateConfig {
    pub window_s: f64,
    pub min_hz: BTreeMap<String, f64>,
}

impl Default for RateConfig {
    fn default() -> Self {
        let topics = [
            "/camera/base/image_raw",
            "/camera/gripper/image_raw",
            "/lidar/points",
            "/odom",
            "/tf",
            "/action",
        ];
        RateConfig {
            window_s: 2.0,
            min_hz: topics.iter().map(|t| (t.to_string(), 9.0)).collect(),
        }
    }
}

impl Default for CollectConfig {
    fn default() -> Self {
        CollectConfig {
            monitors: MonitorConfig {
                move_time_limit: 90.0,
                pick_time_limit: 40.0,
                place_time_limit: 40.0,
                ..MonitorConfig::default()
            },
            rates: RateConfig::default(),
            randomise: true,
        }
    }
}

impl CollectConfig {
    pub fn load(path: &Path) -> Result<CollectConfig, CollectError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| CollectError::Config(format!("{}: {e}", path.display())))?;
        let c: CollectConfig =
            toml::from_str(&text).map_err(|e| CollectError::Config(format!("{}: {e}", path.display())))?;
        c.validate()?;
        Ok(c)
    }

    /// `configs/collect.toml` when present, else the defaults.
    pub fn load_default() -> Result<CollectConfig, CollectError> {
        let path = kitchen_r_sim::config::configs_dir().join("collect.toml");
        if path.is_file() {
            CollectConfig::load(&path)
        } else {
            Ok(CollectConfig::default())
        }
    }

    pub(crate) fn validate(&self) -> Result<(), CollectError> {
        let m = &self.monitors;
        let limits = [m.move_time_limit, m.pick_time_limit, m.place_time_limit];
        if limits.iter().any(|l| !(l.is_finite() && *l > 0.0)) {
            return Err(CollectError::Config(
                "monitors: time limits must be positive".into(),
            ));
        }
        if self.rates.window_s.is_nan()
            || self.rates.window_s <= 0.0
            || self.rates.min_hz.values().any(|h| !(h.is_finite() && *h >= 0.0))
        {
            return Err(CollectError::Config("rates: window_s > 0 and min_hz >= 0".into()));
        }
        Ok(())
    }
}
