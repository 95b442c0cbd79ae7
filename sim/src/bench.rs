//! `kitchen-r bench sim`: physics step time, observation time and the real-time factor of an
//! episode with observations at the policy query rate. Wall-clock figures for people; no test
//! asserts on them.

use std::time::Instant;

/// A stopwatch on this thread's CPU time (`CLOCK_THREAD_CPUTIME_ID`, exact to the nanosecond,
/// unlike the tick-granular `/proc` counters), so figures mean "one core" even on a shared
/// machine; wall time where the platform has no thread clock.
struct Clock {
    wall: Instant,
    cpu: Option<cpu_time::ThreadTime>,
}

impl Clock {
    fn start() -> Clock {
        Clock {
            wall: Instant::now(),
            cpu: cpu_time::ThreadTime::try_now().ok(),
        }
    }

    /// Seconds since start.
    fn secs(&self) -> f64 {
        match &self.cpu {
            Some(t) => t.elapsed().as_secs_f64(),
            None => self.wall.elapsed().as_secs_f64(),
        }
    }
}

use serde::Serialize;

use kitchen_r_core::GraspMode;

use crate::config::{SensorsConfig, SimConfig};
use crate::error::SimError;
use crate::generator::{EpisodeParams, generate};
use crate::sim::{Assets, Sim};
use crate::types::Action;

/// The figures `bench sim --json` prints.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub scene: String,
    /// `thread_cpu` (this thread's CPU time, immune to other load) or `wall`.
    pub timing: &'static str,
    /// One physics substep, robot commanded and moving (µs): the median over `BATCHES` batches
    /// of control steps, so one burst of load on a shared host does not decide the figure.
    pub physics_step_us: f64,
    /// The fastest batch's physics substep (µs): the figure with the least interference.
    pub physics_step_us_min: f64,
    /// The same substep in the physical grasp mode (the fingers force-limited joints of a
    /// multibody rooted at the hand), median and fastest batch (µs).
    pub physics_step_us_articulated: f64,
    pub physics_step_us_articulated_min: f64,
    /// One control step without rendering (µs), median batch.
    pub control_step_us: f64,
    /// One observation: every configured camera plus LiDAR (ms), median over `BATCHES` batches.
    pub observation_ms: f64,
    /// The fastest batch's observation (ms).
    pub observation_ms_min: f64,
    /// Of which the LiDAR scan (ms).
    pub lidar_ms: f64,
    pub cameras: usize,
    pub camera_pixels: u64,
    /// Camera rays per second while observing.
    pub rays_per_second: f64,
    /// Sim time over compute time, stepping with an observation every `query_every` control steps.
    pub realtime_factor: f64,
    pub query_every: u32,
    pub control_steps: u32,
    pub substeps_per_control_step: u32,
    pub bodies: usize,
    pub colliders: usize,
    /// The same physics step and observation with another robot (`bench sim --mesh-robot`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh_robot: Option<MeshRobotReport>,
}

/// Figures with a robot given by file, such as a mounted robosuite arm (seven joints, links
/// colliding as mesh hulls and drawn by the cameras): the physics substep in both grasp modes and
/// the configured cameras' observation with that robot's arm in their view.
#[derive(Debug, Clone, Serialize)]
pub struct MeshRobotReport {
    pub robot: String,
    pub arm_joints: usize,
    /// Arm and hand colliders (mesh hulls and primitives).
    pub arm_colliders: usize,
    pub physics_step_us: f64,
    pub physics_step_us_min: f64,
    /// The same substep in the physical grasp mode (force-limited fingers).
    pub physics_step_us_articulated: f64,
    pub physics_step_us_articulated_min: f64,
    /// Every configured camera, no LiDAR (ms), median and fastest of `BATCHES` batches.
    pub observation_ms: f64,
    pub observation_ms_min: f64,
    pub cameras: usize,
}

/// Timed batches per figure.
const BATCHES: u32 = 5;

/// Median and minimum of a few timings.
fn median_min(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[v.len() / 2], v[0])
}

/// A deterministic, varied action for step `k`: drive, turn, sweep the arm, open and close.
pub fn wobble_action(k: u32) -> Action {
    let t = f64::from(k) * 0.1;
    Action::new(
        0.15 * (0.3 * t).sin(),
        0.4 * (0.17 * t).cos(),
        [
            0.45 + 0.1 * (0.5 * t).sin(),
            0.15 * (0.4 * t).cos(),
            0.95 + 0.1 * (0.3 * t).sin(),
        ],
        [
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
            std::f64::consts::FRAC_1_SQRT_2,
            0.0,
        ],
        if (k / 20).is_multiple_of(2) { 1.0 } else { 0.0 },
    )
}

/// Median and fastest of `BATCHES` batches of `per_batch` unrendered control steps (µs each).
fn control_steps(sim: &mut Sim, per_batch: u32) -> Result<(f64, f64), SimError> {
    let mut control = Vec::new();
    for b in 0..BATCHES {
        let t0 = Clock::start();
        for k in b * per_batch..(b + 1) * per_batch {
            sim.step(&wobble_action(k), false)?;
        }
        control.push(t0.secs() * 1e6 / f64::from(per_batch));
    }
    Ok(median_min(control))
}

/// [`MeshRobotReport`] for the robot `file` on episode `ep`, `steps` control steps.
fn mesh_robot(
    file: &std::path::Path,
    ep: &crate::EpisodeConfig,
    steps: u32,
) -> Result<MeshRobotReport, SimError> {
    let mut sim = mesh_robot_sim(file, ep, GraspMode::Abstract)?;
    let substeps = f64::from(sim.config().physics.substeps);
    let per_batch = (steps / BATCHES).max(1);
    let (step_us, step_min) = control_steps(&mut sim, per_batch)?;
    let (articulated_us, articulated_min) =
        control_steps(&mut mesh_robot_sim(file, ep, GraspMode::Physical)?, per_batch)?;
    let n_obs = 30;
    let (observation_ms, observation_ms_min) = observe_ms(&mut sim, n_obs);
    Ok(MeshRobotReport {
        robot: file.display().to_string(),
        arm_joints: sim.robot.arm.dof,
        arm_colliders: sim.robot.bodies.arm_colliders.len(),
        physics_step_us: step_us / substeps,
        physics_step_us_min: step_min / substeps,
        physics_step_us_articulated: articulated_us / substeps,
        physics_step_us_articulated_min: articulated_min / substeps,
        observation_ms,
        observation_ms_min,
        cameras: sim.sensors.cameras.len(),
    })
}

/// Episode `ep` with the robot `file` in grasp mode `mode` and the configured cameras, without
/// LiDAR.
fn mesh_robot_sim(
    file: &std::path::Path,
    ep: &crate::EpisodeConfig,
    mode: GraspMode,
) -> Result<Sim, SimError> {
    let dir = kitchen_r_core::assets::assets_dir();
    let assets = Assets::load_with_robot(&dir, &crate::RobotConfig { file: file.into() })?;
    let sensors = SensorsConfig {
        lidar: None,
        ..SensorsConfig::load_default()?
    };
    let mut config = SimConfig::load_default()?;
    config.grasp.mode = mode;
    Ok(Sim::new(assets, config, sensors, ep)?.0)
}

/// Milliseconds per full observation (median and fastest of the batches), over `n_obs` of them.
fn observe_ms(sim: &mut Sim, n_obs: u32) -> (f64, f64) {
    let mut observe = Vec::new();
    for _ in 0..BATCHES {
        let t0 = Clock::start();
        for _ in 0..n_obs / BATCHES {
            std::hint::black_box(sim.observe());
        }
        observe.push(t0.secs() * 1e3 / f64::from(n_obs / BATCHES));
    }
    median_min(observe)
}

/// The benchmark's episode: seed 7 on the first scene.
fn first_episode(assets: &Assets) -> Result<(kitchen_r_core::scene::Scene, crate::EpisodeConfig), SimError> {
    let params = EpisodeParams::load_default()?;
    let scene = assets
        .scenes
        .first()
        .ok_or_else(|| SimError::Config("no scenes".into()))?
        .clone();
    let ep = generate(&scene, &assets.catalogue, &params, 7, 0)?;
    Ok((scene, ep))
}

/// Run the benchmark on the first scene for `steps` control steps (and with the robot
/// `mesh_robot` too, when given).
pub fn run(
    steps: u32,
    query_every: u32,
    mesh_robot_file: Option<&std::path::Path>,
) -> Result<BenchReport, SimError> {
    let assets = Assets::load_default()?;
    let config = SimConfig::load_default()?;
    let sensors = SensorsConfig::load_default()?;
    let (scene, ep) = first_episode(&assets)?;
    let mut physical = config.clone();
    physical.grasp.mode = GraspMode::Physical;
    let blind = SensorsConfig {
        cameras: Vec::new(),
        lidar: None,
        ..sensors.clone()
    };
    let (mut articulated, _) = Sim::new(assets.clone(), physical, blind, &ep)?;
    let (mut sim, _) = Sim::new(assets, config, sensors, &ep)?;
    let substeps = sim.config().physics.substeps;

    let per_batch = (steps / BATCHES).max(1);
    let (control_step_us, control_min) = control_steps(&mut sim, per_batch)?;
    let (articulated_us, articulated_min) = control_steps(&mut articulated, per_batch)?;

    let n_obs = 30;
    let (observation_ms, observation_ms_min) = observe_ms(&mut sim, n_obs);
    let lidar_ms = match &sim.sensors.lidar {
        Some(l) => {
            let pose = sim.robot.base_iso(&sim.world);
            let t0 = Clock::start();
            for _ in 0..10 * n_obs {
                std::hint::black_box(crate::sensors::lidar::scan(&sim.world, l, &pose));
            }
            t0.secs() * 1e3 / f64::from(10 * n_obs)
        }
        None => 0.0,
    };
    let pixels: u64 = sim
        .sensors
        .cameras
        .iter()
        .map(|c| u64::from(c.width) * u64::from(c.height))
        .sum();

    let mesh_robot = match mesh_robot_file {
        Some(f) => Some(mesh_robot(f, &ep, steps)?),
        None => None,
    };
    sim.reset(&ep)?;
    let t0 = Clock::start();
    for k in 0..steps {
        sim.step(&wobble_action(k), k % query_every == 0)?;
    }
    let busy = t0.secs();
    Ok(BenchReport {
        scene: scene.id,
        timing: if cpu_time::ThreadTime::try_now().is_ok() {
            "thread_cpu"
        } else {
            "wall"
        },
        physics_step_us: control_step_us / f64::from(substeps),
        physics_step_us_min: control_min / f64::from(substeps),
        physics_step_us_articulated: articulated_us / f64::from(substeps),
        physics_step_us_articulated_min: articulated_min / f64::from(substeps),
        control_step_us,
        observation_ms,
        observation_ms_min,
        lidar_ms,
        cameras: sim.sensors.cameras.len(),
        camera_pixels: pixels,
        rays_per_second: pixels as f64 / ((observation_ms - lidar_ms).max(1e-6) / 1e3),
        realtime_factor: sim.time() / busy,
        query_every,
        control_steps: steps,
        substeps_per_control_step: substeps,
        bodies: sim.world.bodies.len(),
        colliders: sim.world.colliders.len(),
        mesh_robot,
    })
}

impl BenchReport {
    /// One-line JSON (the CLI has no serde_json of its own).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bench's Panda, its hand in the gripper camera's view, renders the bytes it rendered
    /// when each ray was clipped face by face against the link hulls: making the ray caster
    /// faster must not move a pixel. Needs the robosuite wheel (`ROBOSUITE_ASSETS`). The third
    /// image changed with the seven-joint arms' obstacle leaf (`robot::clearance`), which moves
    /// the arm differently there: without the leaf it is the image it was.
    #[test]
    fn the_panda_in_view_renders_the_same_bytes() {
        if kitchen_r_core::assets::robosuite_assets_for_tests().is_none() {
            return;
        }
        let assets = Assets::load_default().unwrap();
        let (_, ep) = first_episode(&assets).unwrap();
        let file =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/robots/robosuite/panda.toml");
        let mut sim = mesh_robot_sim(&file, &ep, GraspMode::Abstract).unwrap();
        let mut hashes = Vec::new();
        for k in 0..60 {
            sim.step(&wobble_action(k), false).unwrap();
            if k % 20 == 19 {
                hashes.push(crate::test_support::image_hash(&sim.observe().images));
            }
        }
        assert_eq!(
            hashes,
            [16098436688272365871, 3026566338621098452, 2659129914132942665]
        );
    }
}
