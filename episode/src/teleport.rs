//! Teleport on failure: after a failed task the robot and objects are put where the expert
//! stood at the start of the next task, so one failure does not fail the rest of the plan. The
//! expert's states come from one privileged run of the oracle over the episode, made before
//! the policy's run; the workers, local evaluation and the Python environment all take them
//! from here.

use kitchen_r_sim::{Action, Assets, EpisodeConfig, Sim, Snapshot, StepInfo};

use crate::oracle::{OraclePolicy, expert_options};
use crate::runner::{RunError, StepHook, run_episode};

/// Collects the world's state at the start of each task.
#[derive(Debug, Default)]
struct Starts(Vec<Snapshot>);

impl StepHook for Starts {
    fn on_step(&mut self, _: &Sim, _: &Action, _: &StepInfo) -> Result<(), String> {
        Ok(())
    }
    fn on_task_start(&mut self, sim: &Sim, index: usize) {
        if self.0.len() == index {
            self.0.push(sim.snapshot());
        }
    }
}

/// Run the expert once over `cfg`, loaded in `sim` and at its start, keeping its state at each
/// task start; then reset `sim` to the episode's start.
pub fn expert_starts(sim: &mut Sim, cfg: &EpisodeConfig, assets: &Assets) -> Result<Vec<Snapshot>, RunError> {
    let mut expert = OraclePolicy::new(assets)
        .without_images()
        .with_grasp_mode(sim.config().grasp.mode);
    let mut starts = Starts::default();
    run_episode(sim, &mut expert, &expert_options(), None, &mut starts)?;
    sim.reset(cfg)?;
    Ok(starts.0)
}
