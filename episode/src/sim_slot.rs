//! One simulator per thread, reused from episode to episode: building one loads meshes and
//! scenes, resetting one does not.

use kitchen_r_sim::{Assets, EpisodeConfig, SensorsConfig, Sim, SimConfig, SimError};

/// `cfg` loaded into the thread's simulator: the one it has, reset, or a new one the first time.
pub fn load<'a>(
    sim: &'a mut Option<Sim>,
    assets: &Assets,
    sim_cfg: &SimConfig,
    sensors: &SensorsConfig,
    cfg: &EpisodeConfig,
) -> Result<&'a mut Sim, SimError> {
    match sim {
        Some(s) => {
            s.reset(cfg)?;
            Ok(s)
        }
        None => Ok(sim.insert(Sim::new(assets.clone(), sim_cfg.clone(), sensors.clone(), cfg)?.0)),
    }
}
