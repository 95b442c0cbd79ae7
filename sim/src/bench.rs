//! `kitchen-r bench sim`: physics step time, observation time and the real-time factor of an
//! episode with observations at the policy query rate. Wall-clock figures for people; no test
//! asserts on them.

use std::time::Instant;

/// A stopwatch on this thread's CPU time where Linux exposes it (`/proc/thread-self/schedstat`),
/// so figures mean "one core" even on a shared machine; wall time elsewhere.
struct Clock {
    wall: Instant,
    cpu: Option<u64>,
}

fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

impl Clock {
    fn start() -> Clock {
        Clock {
            wall: Instant::now(),
            cpu: thread_cpu_ns(),
        }
    }

    /// Seconds since start.
    fn secs(&self) -> f64 {
        match (self.cpu, thread_cpu_ns()) {
            (Some(a), Some(b)) => (b - a) as f64 * 1e-9,
            _ => self.wall.elapsed().as_secs_f64(),
        }
    }
}

use serde::Serialize;

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
    /// Mean wall time of one physics substep, robot commanded and moving (µs).
    pub physics_step_us: f64,
    /// Mean wall time of one control step without rendering (µs).
    pub control_step_us: f64,
    /// Mean wall time of one observation: every configured camera plus LiDAR (ms).
    pub observation_ms: f64,
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

/// Run the benchmark on the first scene for `steps` control steps.
pub fn run(steps: u32, query_every: u32) -> Result<BenchReport, SimError> {
    let assets = Assets::load_default()?;
    let config = SimConfig::load_default()?;
    let sensors = SensorsConfig::load_default()?;
    let params = EpisodeParams::load_default()?;
    let scene = assets
        .scenes
        .first()
        .ok_or_else(|| SimError::Config("no scenes".into()))?
        .clone();
    let ep = generate(&scene, &assets.catalogue, &params, 7, 0)?;
    let (mut sim, _) = Sim::new(assets, config, sensors, &ep)?;
    let substeps = sim.config().physics.substeps;

    let t0 = Clock::start();
    for k in 0..steps {
        sim.step(&wobble_action(k), false)?;
    }
    let control_step_us = t0.secs() * 1e6 / f64::from(steps);

    let n_obs = 30;
    let t0 = Clock::start();
    for _ in 0..n_obs {
        std::hint::black_box(sim.observe());
    }
    let observation_ms = t0.secs() * 1e3 / f64::from(n_obs);
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

    sim.reset(&ep)?;
    let t0 = Clock::start();
    for k in 0..steps {
        sim.step(&wobble_action(k), k % query_every == 0)?;
    }
    let busy = t0.secs();
    Ok(BenchReport {
        scene: scene.id,
        timing: if thread_cpu_ns().is_some() {
            "thread_cpu"
        } else {
            "wall"
        },
        physics_step_us: control_step_us / f64::from(substeps),
        control_step_us,
        observation_ms,
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
    })
}

impl BenchReport {
    /// One-line JSON (the CLI has no serde_json of its own).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|e| format!("{{\"error\":\"{e}\"}}"))
    }
}
