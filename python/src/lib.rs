//! `gym_kitchen_r._native`: the twin's episodes for Python, behind the `gym_kitchen_r` package's
//! gymnasium environment (`python/gym_kitchen_r/env.py`).
//!
//! It owns the translation between Python values and the episode crate's types, nothing else:
//! episodes are `kitchen_r_episode::driven` episodes, i.e. `run_episode` with the action
//! relayed from Python, so the same instruction and seed give the episode `kitchen-r eval` and
//! the leaderboard's workers run. It must not add rules: no success check, time limit or action
//! rule of its own. The simulator steps with the GIL released.

mod convert;
mod live;
mod samples;

use std::sync::{Mutex, MutexGuard, PoisonError};

use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_core::observations::PrivilegedScope;
use kitchen_r_episode::driven::{DriveError, DriveOptions, DrivenEpisode, Progress};
use kitchen_r_episode::eval::instructions;
use kitchen_r_episode::runner::RunOptions;
use kitchen_r_episode::samples::instruction_episode;
use kitchen_r_sim::seeds::instruction_seed;
use kitchen_r_sim::{Assets, EpisodeParams, SensorsConfig, Sim, SimConfig};
use pyo3::exceptions::{PyKeyError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// What the environment holds between calls.
struct Inner {
    assets: Assets,
    params: EpisodeParams,
    sim_cfg: SimConfig,
    sensors: SensorsConfig,
    instructions: Vec<Instruction>,
    opts: DriveOptions,
    /// Apply the paper's randomisation (`configs/episodes.toml` `[randomise]`) to each episode,
    /// as collection and `kitchen-r episodes generate` do, from the same episode seed.
    randomise: bool,
    /// A simulator between episodes (built once, reset for each episode as `eval` does).
    idle: Option<Sim>,
    episode: Option<DrivenEpisode>,
    /// `ros2=True`: each episode published live as ROS 2 topics (`live`).
    live: Option<live::Live>,
}

/// Errors of this layer, mapped once to Python exceptions.
#[derive(Debug, thiserror::Error)]
enum EnvError {
    #[error("{0}")]
    Drive(#[from] DriveError),
    #[error("no instruction {0:?} in this split (see instruction_ids())")]
    UnknownInstruction(String),
    #[error("plan step {0} does not exist: instruction {1:?} has {2} steps")]
    NoTask(usize, String, usize),
    #[error("call reset() before step()")]
    NotReset,
    #[error("an action has {0} values; it must have 10 (v, w, x, y, z, qw, qx, qy, qz, g)")]
    ActionShape(usize),
    #[error("{0}")]
    Setup(String),
}

impl EnvError {
    /// The Python exception, its message led by `context` (which environment of several).
    fn into_py(self, context: &str) -> PyErr {
        let msg = format!("{context}{self}");
        match self {
            EnvError::Drive(DriveError::BadAction(_)) | EnvError::ActionShape(_) => {
                PyValueError::new_err(msg)
            }
            EnvError::UnknownInstruction(_) => PyKeyError::new_err(msg),
            EnvError::NoTask(..) => PyValueError::new_err(msg),
            _ => PyRuntimeError::new_err(msg),
        }
    }
}

impl From<EnvError> for PyErr {
    fn from(e: EnvError) -> PyErr {
        e.into_py("")
    }
}

fn setup<E: std::fmt::Display>(what: &str) -> impl Fn(E) -> EnvError + '_ {
    move |e| EnvError::Setup(format!("{what}: {e}"))
}

/// One environment: one simulator, one episode at a time.
#[pyclass(module = "gym_kitchen_r._native")]
struct NativeEnv {
    inner: Mutex<Inner>,
    /// Observations carry depth images (fixed at construction, read without the lock).
    depth: bool,
    /// What decisions carry besides the observation.
    show: convert::Show,
    /// Frames each observation stacks.
    history: usize,
}

impl NativeEnv {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic while stepping leaves the episode to be reset; the data is still whole.
        self.inner.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

impl Inner {
    /// Launch the episode of `instruction` with run seed `seed`; `receive` waits for its first
    /// decision.
    fn begin_reset(&mut self, instruction: &str, seed: u64, task: Option<usize>) -> Result<(), EnvError> {
        if let Some(old) = self.episode.take() {
            self.idle = old.finish().or(self.idle.take());
        }
        let ins = self.find(instruction)?;
        check_task(ins, task)?;
        let episode_seed = instruction_seed(seed, &ins.id);
        let cfg = instruction_episode(&self.assets, &self.params, ins, episode_seed, self.randomise)
            .map_err(setup("episode"))?;
        let sim = match self.idle.take() {
            Some(s) => s,
            None => {
                (Sim::new(
                    self.assets.clone(),
                    self.sim_cfg.clone(),
                    self.sensors.clone(),
                    &cfg,
                ))
                .map_err(setup("simulator"))?
                .0
            }
        };
        let watch = (self.live.as_mut())
            .map(|l| l.watch().map_err(EnvError::Setup))
            .transpose()?;
        let opts = DriveOptions {
            only_task: task,
            watch,
            ..self.opts.clone()
        };
        self.episode = Some(DrivenEpisode::launch(sim, cfg, &self.assets, &opts)?);
        Ok(())
    }

    fn find(&self, instruction: &str) -> Result<&Instruction, EnvError> {
        (self.instructions.iter().find(|i| i.id == instruction))
            .ok_or_else(|| EnvError::UnknownInstruction(instruction.to_string()))
    }

    fn check_reset(&self, instruction: &str, task: Option<usize>) -> Result<(), EnvError> {
        check_task(self.find(instruction)?, task)
    }

    fn episode(&mut self) -> Result<&mut DrivenEpisode, EnvError> {
        self.episode.as_mut().ok_or(EnvError::NotReset)
    }

    fn check_action(&mut self, action: &[f64]) -> Result<[f64; 10], EnvError> {
        let a: [f64; 10] = action
            .try_into()
            .map_err(|_| EnvError::ActionShape(action.len()))?;
        self.episode()?.check_action(a)?;
        Ok(a)
    }

    fn begin_step(&mut self, action: &[f64]) -> Result<(), EnvError> {
        let a = self.check_action(action)?;
        Ok(self.episode()?.send_action(a)?)
    }

    fn receive(&mut self) -> Result<Progress, EnvError> {
        Ok(self.episode()?.receive()?)
    }

    /// As `receive`, asleep while waiting: `step_many` waits for several episodes at once.
    fn receive_sleeping(&mut self) -> Result<Progress, EnvError> {
        Ok(self.episode()?.receive_sleeping()?)
    }

    fn expert_chunk(&mut self) -> Result<Vec<[f64; 10]>, EnvError> {
        Ok(self.episode()?.expert_chunk()?)
    }
}

fn check_task(ins: &Instruction, task: Option<usize>) -> Result<(), EnvError> {
    match task {
        Some(j) if j >= ins.plan.len() => Err(EnvError::NoTask(j, ins.id.clone(), ins.plan.len())),
        _ => Ok(()),
    }
}

/// The split, its instructions (the test split's from the organiser's `ground_truth` file),
/// after checking the task time limit: what an environment and a sample stream start from.
fn split_instructions(
    split: &str,
    ground_truth: Option<&std::path::PathBuf>,
    task_time_limit: f64,
) -> PyResult<(Split, Vec<Instruction>)> {
    let split: Split = split.parse().map_err(PyValueError::new_err)?;
    if !(task_time_limit.is_finite() && task_time_limit > 0.0) {
        return Err(PyValueError::new_err(
            "task_time_limit must be a positive number of seconds",
        ));
    }
    let ins = instructions(split, ground_truth).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok((split, ins))
}

/// What `step_many` asks of one environment.
#[derive(FromPyObject)]
enum Request {
    /// Execute this action.
    Step(Vec<f64>),
    /// Start the episode of `(instruction, run seed, plan step or None)`.
    Reset(String, u64, Option<usize>),
}

/// Step or reset several environments at once: every action is checked first (a bad one
/// raises before any environment moves), then all are handed to their episodes' threads and
/// simulate in parallel with the GIL released, then each result is converted. The vector
/// environment's step.
#[pyfunction]
fn step_many<'py>(
    py: Python<'py>,
    envs: Vec<PyRef<'py, NativeEnv>>,
    requests: Vec<Request>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    if envs.len() != requests.len() {
        return Err(PyValueError::new_err(format!(
            "{} requests for {} environments",
            requests.len(),
            envs.len()
        )));
    }
    let refs: Vec<&NativeEnv> = envs.iter().map(|e| &**e).collect();
    for (i, a) in refs.iter().enumerate() {
        if refs[..i].iter().any(|b| std::ptr::eq(*a, *b)) {
            return Err(PyValueError::new_err(format!(
                "environment {i} appears twice: each request needs an environment of its own"
            )));
        }
    }
    let done = py.detach(|| -> Result<Vec<Progress>, (usize, EnvError)> {
        let mut inners: Vec<MutexGuard<'_, Inner>> = refs.iter().map(|e| e.lock()).collect();
        for (i, (inner, r)) in inners.iter_mut().zip(&requests).enumerate() {
            match r {
                Request::Step(a) => inner.check_action(a).map(drop),
                Request::Reset(id, _, task) => inner.check_reset(id, *task),
            }
            .map_err(|e| (i, e))?;
        }
        for (i, (inner, r)) in inners.iter_mut().zip(&requests).enumerate() {
            match r {
                Request::Step(a) => inner.begin_step(a),
                Request::Reset(id, seed, task) => inner.begin_reset(id, *seed, *task),
            }
            .map_err(|e| (i, e))?;
        }
        (inners.iter_mut().enumerate())
            .map(|(i, inner)| inner.receive_sleeping().map_err(|e| (i, e)))
            .collect()
    });
    let done = done.map_err(|(i, e)| e.into_py(&format!("environment {i}: ")))?;
    (done.iter().zip(&refs))
        .map(|(p, e)| convert::progress(py, p, e.history, e.depth, &e.show))
        .collect()
}

#[pymethods]
impl NativeEnv {
    /// `split`: `dev` (the public split with plans) or `test` with `ground_truth` (a JSON Lines
    /// file of instructions with plans, the organiser's). See `gym_kitchen_r.KitchenREnv`.
    #[new]
    #[pyo3(signature = (split="dev", ground_truth=None, images=true, depth=false, teleport_on_failure=true, history=1, task_time_limit=120.0, max_tasks=0, expert=true, expert_inline=false, privileged=false, privileged_observation=false, randomise=false, grasp_mode=None, ros2=false, ros2_config=None, ros2_wait=0.0))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        split: &str,
        ground_truth: Option<std::path::PathBuf>,
        images: bool,
        depth: bool,
        teleport_on_failure: bool,
        history: usize,
        task_time_limit: f64,
        max_tasks: usize,
        expert: bool,
        expert_inline: bool,
        privileged: bool,
        privileged_observation: bool,
        randomise: bool,
        grasp_mode: Option<&str>,
        ros2: bool,
        ros2_config: Option<std::path::PathBuf>,
        ros2_wait: f64,
    ) -> PyResult<NativeEnv> {
        if !(1..=8).contains(&history) {
            return Err(PyValueError::new_err("history must be 1 to 8 control steps"));
        }
        let (split, instructions) = split_instructions(split, ground_truth.as_ref(), task_time_limit)?;
        let assets = Assets::load_default().map_err(setup("assets"))?;
        let params = EpisodeParams::load_default().map_err(setup("episode parameters"))?;
        let mut sim_cfg = SimConfig::load_default().map_err(setup("configs/sim.toml"))?;
        // The grasp mode as a server's `[control] grasp` sets it; None keeps sim.toml's.
        if let Some(mode) = grasp_mode {
            sim_cfg.grasp.mode = mode.parse().map_err(PyValueError::new_err)?;
        }
        let sensors = SensorsConfig::load_default().map_err(setup("configs/sensors.toml"))?;
        let live = match ros2 {
            true => Some(live::start(py, ros2_config.as_deref(), &sensors, ros2_wait)?),
            false => None,
        };
        let opts = DriveOptions {
            run: RunOptions {
                task_time_limit,
                max_tasks: (max_tasks > 0).then_some(max_tasks),
                ..RunOptions::default()
            },
            teleport_on_failure,
            images: images || depth,
            depth,
            observation_history: history,
            expert: expert || expert_inline,
            expert_inline,
            only_task: None,
            watch: None,
        };
        Ok(NativeEnv {
            inner: Mutex::new(Inner {
                assets,
                params,
                sim_cfg,
                sensors,
                instructions,
                opts,
                randomise,
                idle: None,
                episode: None,
                live,
            }),
            depth,
            show: convert::Show {
                privileged,
                privileged_observation: privileged_observation.then(|| PrivilegedScope::for_split(split)),
            },
            history,
        })
    }

    /// The split's instruction ids, in dataset order.
    fn instruction_ids(&self) -> Vec<String> {
        self.lock().instructions.iter().map(|i| i.id.clone()).collect()
    }

    /// The instruction text and ground-truth plan of `instruction`.
    fn instruction<'py>(&self, py: Python<'py>, instruction: &str) -> PyResult<Bound<'py, PyDict>> {
        let inner = self.lock();
        let ins = (inner.instructions.iter().find(|i| i.id == instruction))
            .ok_or_else(|| EnvError::UnknownInstruction(instruction.to_string()))?;
        let d = PyDict::new(py);
        d.set_item("id", &ins.id)?;
        d.set_item("scene", &ins.scene)?;
        d.set_item("instruction", &ins.instruction)?;
        d.set_item("plan", &ins.plan)?;
        Ok(d)
    }

    /// The configured cameras: `(name, height, width)` each, in observation order.
    fn cameras(&self) -> Vec<(String, u32, u32)> {
        let inner = self.lock();
        (inner.sensors.cameras.iter())
            .map(|c| (c.name.clone(), c.height, c.width))
            .collect()
    }

    /// Start the episode of `instruction` with run seed `seed` (the episode `kitchen-r eval
    /// --seed SEED` runs for it); the first decision. With `task`, only that plan step, from
    /// the expert's state at its start.
    #[pyo3(signature = (instruction, seed, task=None))]
    fn reset<'py>(
        &self,
        py: Python<'py>,
        instruction: &str,
        seed: u64,
        task: Option<usize>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let progress = py.detach(|| {
            let mut inner = self.lock();
            inner.begin_reset(instruction, seed, task)?;
            inner.receive()
        })?;
        convert::progress(py, &progress, self.history, self.depth, &self.show)
    }

    /// Execute one action (10 values) for one control step.
    fn step<'py>(&self, py: Python<'py>, action: Vec<f64>) -> PyResult<Bound<'py, PyDict>> {
        let progress = py.detach(|| {
            let mut inner = self.lock();
            inner.begin_step(&action)?;
            inner.receive()
        })?;
        convert::progress(py, &progress, self.history, self.depth, &self.show)
    }

    /// The expert's chunk (16 actions of 10 values) for the current decision.
    fn expert_chunk(&self, py: Python<'_>) -> PyResult<Vec<Vec<f64>>> {
        let chunk = py.detach(|| self.lock().expert_chunk())?;
        Ok(chunk.iter().map(|a| a.to_vec()).collect())
    }

    /// Stop the current episode, if any, and let go of the ROS 2 publisher (the next reset
    /// takes it again).
    fn close(&self, py: Python<'_>) {
        py.detach(|| {
            let mut inner = self.lock();
            if let Some(old) = inner.episode.take() {
                inner.idle = old.finish().or(inner.idle.take());
            }
            if let Some(l) = inner.live.as_mut() {
                l.release();
            }
        });
    }

    /// `ros2=True`: `(domain id, samples written to DDS, samples DDS dropped)` of the
    /// process's publisher; `None` without ros2 or after `close()`.
    fn ros2_counts(&self) -> Option<(u16, u64, u64)> {
        self.lock().live.as_ref().and_then(|l| l.counts())
    }
}

#[pymodule]
mod _native {
    #[pymodule_export]
    use super::samples::NativeSamples;
    #[pymodule_export]
    use super::{NativeEnv, step_many};
    #[pymodule_export]
    const STATE_FIELDS: [&str; 29] = super::convert::STATE_FIELDS;
}
