//! Tests' shared start: the twin on the first dev instruction with the default configs.

use kitchen_r_core::dataset::Split;
use kitchen_r_episode::eval::{episode_configs, instructions};
use kitchen_r_sim::{Assets, SensorsConfig, Sim, SimConfig};

/// The assets and a simulator reset to the first dev episode (seed 0).
pub(crate) fn first_dev_sim() -> (Assets, Sim) {
    let assets = Assets::load_default().unwrap();
    let dev = instructions(Split::Dev, None).unwrap();
    let cfg = &episode_configs(&assets, &dev[..1], 0, None).unwrap()[0];
    let sensors = SensorsConfig::load_default().unwrap();
    let (sim, _) = Sim::new(assets.clone(), SimConfig::load_default().unwrap(), sensors, cfg).unwrap();
    (assets, sim)
}
