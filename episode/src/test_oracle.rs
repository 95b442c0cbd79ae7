//! Tests' shared check: the oracle, blind (no cameras or LiDAR: it needs none), completes every
//! task of an episode.

use kitchen_r_core::dataset::Instruction;
use kitchen_r_sim::{Assets, EpisodeConfig, SensorsConfig, Sim, SimConfig};

use crate::oracle::OraclePolicy;
use crate::runner::{RunOptions, run_episode};

/// Copy the shipped robot (its description and sidecar) from the assets directory `src` into the
/// assets directory `dir`.
pub(crate) fn copy_shipped_robot(src: &std::path::Path, dir: &std::path::Path) {
    let urdf = std::path::Path::new(kitchen_r_core::robot::SHIPPED);
    std::fs::create_dir_all(dir.join(urdf.parent().unwrap())).unwrap();
    for f in [urdf.to_path_buf(), urdf.with_extension("toml")] {
        std::fs::copy(src.join(&f), dir.join(&f)).unwrap();
    }
}

/// The twin of `cfg` without cameras or LiDAR: the oracle reads only privileged state.
pub(crate) fn blind_sim(assets: &Assets, cfg: &EpisodeConfig) -> Sim {
    blind_sim_with(assets, SimConfig::load_default().unwrap(), cfg)
}

/// [`blind_sim`] with the simulator configuration `config` (a grasp mode, say).
pub(crate) fn blind_sim_with(assets: &Assets, config: SimConfig, cfg: &EpisodeConfig) -> Sim {
    let blind = SensorsConfig {
        cameras: Vec::new(),
        lidar: None,
        ..SensorsConfig::default()
    };
    Sim::new(assets.clone(), config, blind, cfg).unwrap().0
}

/// Run `cfg` (the episode of `ins`) with the privileged oracle and assert every task succeeds.
pub(crate) fn assert_oracle_completes(assets: &Assets, cfg: &EpisodeConfig, ins: &Instruction) {
    let mut sim = blind_sim(assets, cfg);
    let run = RunOptions {
        privileged: true,
        ..RunOptions::default()
    };
    let mut oracle = OraclePolicy::new(assets);
    let out = run_episode(&mut sim, &mut oracle, &run, None, &mut ()).unwrap();
    assert_eq!(out.tasks.len(), ins.plan.len());
    assert!(out.tasks.iter().all(|t| t.success), "{}: {:?}", ins.id, out.tasks);
    // Undisturbed, the state never leaves the oracle's plan: it never re-plans.
    assert_eq!(
        oracle.replans(),
        0,
        "{}: the oracle re-planned in its own episode",
        ins.id
    );
}
