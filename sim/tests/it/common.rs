//! Shared fixtures for the twin's integration tests.

use kitchen_r_sim::config::{SensorsConfig, SimConfig};
use kitchen_r_sim::episode::{EpisodeConfig, ObjectPlacement};
use kitchen_r_sim::world::Style;
use kitchen_r_sim::{Action, Assets, Sim};

pub(crate) const DOWN: [f64; 4] = [
    std::f64::consts::FRAC_1_SQRT_2,
    0.0,
    std::f64::consts::FRAC_1_SQRT_2,
    0.0,
];

pub(crate) fn assets() -> Assets {
    Assets::load_default().unwrap()
}

/// Sensors without cameras or LiDAR, so tests that do not look stay fast.
pub(crate) fn blind() -> SensorsConfig {
    SensorsConfig {
        cameras: Vec::new(),
        lidar: None,
        ..SensorsConfig::default()
    }
}

/// kitchen_a with the given key objects and the robot at `start`, no background, no plan.
pub(crate) fn episode(assets: &Assets, start: [f64; 3], objects: Vec<ObjectPlacement>) -> EpisodeConfig {
    let scene = assets.scene("kitchen_a").unwrap();
    EpisodeConfig {
        id: "test".into(),
        scene: scene.id.clone(),
        seed: 0,
        robot_start: start,
        objects,
        background: Vec::new(),
        style: Style::of(scene),
        plan: Vec::new(),
        place_targets: Vec::new(),
    }
}

pub(crate) fn cup_at(x: f64, y: f64, surface: f64) -> ObjectPlacement {
    ObjectPlacement {
        name: "red cup".into(),
        model: "cup".into(),
        color: [0.8, 0.1, 0.1],
        position: [x, y, surface + 0.05],
        yaw: 0.0,
    }
}

pub(crate) fn sim(ep: &EpisodeConfig, sensors: SensorsConfig) -> Sim {
    Sim::new(assets(), SimConfig::load_default().unwrap(), sensors, ep)
        .unwrap()
        .0
}

/// Hold the base still, the TCP at `pos` pointing down, gripper `g`.
pub(crate) fn hold(pos: [f64; 3], g: f64) -> Action {
    Action::new(0.0, 0.0, pos, DOWN, g)
}
