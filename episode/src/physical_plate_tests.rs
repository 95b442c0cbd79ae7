//! The plate in the physical grasp mode (docs/twin/robot.md, "The physical grasp"): the twin
//! builds the catalogue's `[object.physical]` plate, a light dish whose rim the pads pinch, and
//! the oracle picks it. The abstract mode's 0.4 kg solid disc was never picked in this mode (0 of
//! 20 dev picks): a pinch at its edge holds about half its weight's turning moment.

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_sim::{Assets, SimConfig};

use crate::eval::{episode_configs, instructions};
use crate::oracle::OraclePolicy;
use crate::runner::{RunOptions, run_episode};
use crate::test_oracle::blind_sim_with;

/// dev-0015: two moves, "pick the plate", and a move with it in hand.
#[test]
fn the_oracle_picks_the_plate_in_the_physical_grasp_mode() {
    let assets = Assets::load_default().unwrap();
    let ins: Vec<_> = instructions(Split::Dev, None)
        .unwrap()
        .into_iter()
        .filter(|i| i.id == "dev-0015")
        .collect();
    assert!(
        ins[0].plan.iter().any(|s| s == "pick the plate"),
        "dev-0015 changed: {:?}",
        ins[0].plan
    );
    let cfg = &episode_configs(&assets, &ins, 0, None).unwrap()[0];
    let mut config = SimConfig::load_default().unwrap();
    config.grasp.mode = GraspMode::Physical;
    let mut sim = blind_sim_with(&assets, config, cfg);
    let run = RunOptions {
        privileged: true,
        ..RunOptions::default()
    };
    let mut oracle = OraclePolicy::new(&assets).with_grasp_mode(GraspMode::Physical);
    let out = run_episode(&mut sim, &mut oracle, &run, None, &mut ()).unwrap();
    let pick = out.tasks.iter().find(|t| t.step == "pick the plate").unwrap();
    assert!(pick.success, "{pick:?}");
}
