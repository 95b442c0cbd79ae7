//! The sidecar of a robot description: `<name>.toml` beside `<name>.urdf` (or `<name>.xml`), for
//! what neither URDF nor MJCF can say. A TOML file rather than custom XML elements, so the
//! description stays a plain URDF/MJCF file that any tool opens, and so the twin's own settings
//! are read with the same schema checks as every other TOML file of the benchmark.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::ContentError;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sidecar {
    pub frames: Frames,
    pub base: Base,
    pub arm: Arm,
    pub gripper: Gripper,
}

/// Which frames (URDF links, MJCF bodies or sites) the twin's frames are.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Frames {
    /// The robot base frame: origin at the base's centre on the floor, x forward, z up.
    pub base: String,
    /// The tool centre point between the fingertips: x out of the fingers, y their closing axis.
    pub tool: String,
}

/// The differential-drive base's navigation footprint and command limits.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Base {
    /// Radius of the circle around the base centre that planners inflate obstacles by (m).
    pub radius: f64,
    /// m/s, rad/s, m/s², rad/s².
    pub max_v: f64,
    pub max_omega: f64,
    pub acc_v: f64,
    pub acc_omega: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Arm {
    /// Joint configuration after reset (rad), base to tool.
    pub home: Vec<f64>,
    /// Velocity (rad/s) and effort (N·m) limits, base to tool, for formats whose joints carry
    /// none (MJCF); the description's own limits win.
    #[serde(default)]
    pub max_velocity: Option<Vec<f64>>,
    #[serde(default)]
    pub effort: Option<Vec<f64>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gripper {
    /// How fast the finger gap may change (m/s).
    pub opening_speed: f64,
    /// The abstract grasp closes when the commanded opening falls below this (0..1) and lets go
    /// when it rises above `release_threshold`.
    pub grasp_threshold: f64,
    pub release_threshold: f64,
}

impl Sidecar {
    /// The sidecar of the description at `description`: the same path with `.toml`.
    pub fn path(description: &Path) -> PathBuf {
        description.with_extension("toml")
    }

    pub fn load(description: &Path) -> Result<Sidecar, ContentError> {
        let path = Sidecar::path(description);
        let text = std::fs::read_to_string(&path).map_err(|e| ContentError::Invalid {
            path: description.to_path_buf(),
            message: format!(
                "cannot read its sidecar {} ({e}): a robot description needs one beside it with [frames], \
                 [base], [arm] and [gripper] (docs/twin/robot.md)",
                path.display()
            ),
        })?;
        toml::from_str(&text).map_err(|e| ContentError::Parse {
            path,
            message: e.to_string(),
        })
    }
}
