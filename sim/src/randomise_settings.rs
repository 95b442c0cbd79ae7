//! `[randomise]` of `configs/episodes.toml`: which aspects of an episode are randomised and
//! within which ranges. The episode generator holds them; `randomise.rs` draws with them.

use serde::{Deserialize, Serialize};

use crate::error::SimError;

/// `[randomise]` of `configs/episodes.toml`: one switch per aspect, and the ranges.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Randomise {
    /// Key objects within `radius` of their start point, yaw within `yaw_range_deg`.
    pub object_pose: bool,
    /// Object colour variants and jitter, floor, wall and furniture colour jitter.
    pub colors: bool,
    /// Floor tile size and the floor, wall and furniture patterns.
    pub textures: bool,
    /// Light direction and intensity.
    pub lights: bool,
    /// Background objects: models, colours, poses.
    pub background: bool,
    /// Robot start on the start segments (off: the first segment's midpoint).
    pub robot_start: bool,
    /// Key-object yaw is drawn within ± this of its given yaw (degrees; 180 = any).
    pub yaw_range_deg: f64,
    /// Max per-channel change of key-object colours.
    pub object_color_jitter: f32,
    /// Max per-channel change of each furniture item's colour.
    pub furniture_jitter: f32,
    /// Brightness contrast of drawn patterns.
    pub pattern_contrast: [f32; 2],
    /// Light elevation above the horizon (degrees); the azimuth is any.
    pub light_elevation_deg: [f64; 2],
    /// Ambient and diffuse light intensity.
    pub ambient: [f64; 2],
    pub diffuse: [f64; 2],
}

impl Default for Randomise {
    fn default() -> Self {
        Randomise {
            object_pose: true,
            colors: true,
            textures: true,
            lights: true,
            background: true,
            robot_start: true,
            yaw_range_deg: 180.0,
            object_color_jitter: 0.05,
            furniture_jitter: 0.1,
            pattern_contrast: [0.04, 0.16],
            light_elevation_deg: [35.0, 75.0],
            ambient: [0.35, 0.55],
            diffuse: [0.45, 0.75],
        }
    }
}

impl Randomise {
    /// Every aspect off.
    pub fn off() -> Randomise {
        Randomise {
            object_pose: false,
            colors: false,
            textures: false,
            lights: false,
            background: false,
            robot_start: false,
            ..Randomise::default()
        }
    }

    /// Ranges ordered and finite, jitters in [0, 1].
    pub fn validate(&self) -> Result<(), SimError> {
        let ordered = |r: [f64; 2]| r[0].is_finite() && r[1].is_finite() && r[0] <= r[1];
        let ok = ordered(self.light_elevation_deg)
            && ordered(self.ambient)
            && ordered(self.diffuse)
            && ordered(self.pattern_contrast.map(f64::from))
            && (0.0..=180.0).contains(&self.yaw_range_deg)
            && (0.0..=1.0).contains(&self.object_color_jitter)
            && (0.0..=1.0).contains(&self.furniture_jitter);
        if ok {
            Ok(())
        } else {
            Err(SimError::Config(
                "episodes [randomise]: ranges [low, high] with low <= high, yaw_range_deg in 0..=180, \
                 jitters in 0..=1"
                    .into(),
            ))
        }
    }
}
