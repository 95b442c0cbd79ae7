//! `ExpertSamples`' native side: a [`SampleStream`] handed to Python one episode at a time.

use std::path::PathBuf;
use std::sync::Mutex;

use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_core::observations::PrivilegedScope;
use kitchen_r_episode::runner::RunOptions;
use kitchen_r_episode::samples::{EpisodeSamples, SampleOptions, SampleStream};
use kitchen_r_sim::Assets;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert::{self, View};

/// A stream of expert episodes, each with its samples (see `gym_kitchen_r.ExpertSamples`).
#[pyclass(module = "gym_kitchen_r._native")]
pub(crate) struct NativeSamples {
    stream: Mutex<Option<SampleStream>>,
    history: usize,
    depth: bool,
    /// Samples carry the privileged track's observation, with the split's scope.
    privileged_observation: Option<PrivilegedScope>,
}

#[pymethods]
impl NativeSamples {
    #[new]
    #[pyo3(signature = (split="dev", ground_truth=None, episodes=1, seed=0, workers=1, execute=8, history=1, images=true, depth=false, randomise=true, successful_only=true, task_time_limit=120.0, max_tasks=0, shard_index=0, shard_count=1, privileged_observation=false, instructions=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        split: &str,
        ground_truth: Option<PathBuf>,
        episodes: usize,
        seed: u64,
        workers: usize,
        execute: usize,
        history: usize,
        images: bool,
        depth: bool,
        randomise: bool,
        successful_only: bool,
        task_time_limit: f64,
        max_tasks: usize,
        shard_index: usize,
        shard_count: usize,
        privileged_observation: bool,
        instructions: Option<Vec<String>>,
    ) -> PyResult<NativeSamples> {
        let (split, ins) = crate::split_instructions(split, ground_truth.as_ref(), task_time_limit)?;
        let ins = match instructions {
            Some(ids) => only(ins, &ids, split)?,
            None => ins,
        };
        let assets = Assets::load_default().map_err(|e| PyRuntimeError::new_err(format!("assets: {e}")))?;
        let opts = SampleOptions {
            seed,
            episodes,
            workers,
            execute,
            observation_history: history,
            images: images || depth,
            randomise,
            successful_only,
            run: RunOptions {
                task_time_limit,
                max_tasks: (max_tasks > 0).then_some(max_tasks),
                ..RunOptions::default()
            },
            shard: (shard_index, shard_count),
        };
        let stream =
            SampleStream::start(assets, ins, opts).map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(NativeSamples {
            stream: Mutex::new(Some(stream)),
            history,
            depth,
            privileged_observation: privileged_observation.then(|| PrivilegedScope::for_split(split)),
        })
    }

    /// The next episode (simulated with the GIL released), or `None` after the last.
    fn next_episode<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let next = py.detach(|| {
            let mut guard = self
                .stream
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            guard.as_mut().and_then(Iterator::next)
        });
        match next {
            None => Ok(None),
            Some(Err(e)) => Err(PyRuntimeError::new_err(e.to_string())),
            Some(Ok(ep)) => episode(py, &ep, self).map(Some),
        }
    }

    /// Stop the simulator threads (the stream ends).
    fn close(&self, py: Python<'_>) {
        let stream = self
            .stream
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take();
        py.detach(move || drop(stream));
    }
}

/// The split's instructions named by `ids`, in that order (a training set that leaves the
/// held-out instructions out); an id the split lacks is an error that names it.
fn only(ins: Vec<Instruction>, ids: &[String], split: Split) -> PyResult<Vec<Instruction>> {
    if ids.is_empty() {
        return Err(PyValueError::new_err(
            "instructions is empty: name at least one instruction id, or pass None for all",
        ));
    }
    ids.iter()
        .map(|id| {
            ins.iter()
                .find(|i| &i.id == id)
                .cloned()
                .ok_or_else(|| PyValueError::new_err(format!("no instruction {id:?} in the {split} split")))
        })
        .collect()
}

fn episode<'py>(py: Python<'py>, ep: &EpisodeSamples, how: &NativeSamples) -> PyResult<Bound<'py, PyDict>> {
    let (history, depth) = (how.history, how.depth);
    let d = PyDict::new(py);
    d.set_item("index", ep.index)?;
    d.set_item("episode_id", &ep.config.id)?;
    d.set_item("instruction_id", &ep.instruction_id)?;
    d.set_item("seed", ep.config.seed)?;
    d.set_item("scene", &ep.config.scene)?;
    d.set_item("plan", &ep.config.plan)?;
    let tasks = PyList::empty(py);
    for t in &ep.outcome.tasks {
        tasks.append(convert::task(py, t)?)?;
    }
    d.set_item("tasks", tasks)?;
    d.set_item("sim_time", ep.outcome.sim_time)?;
    let samples = PyList::empty(py);
    for s in &ep.samples {
        let sd = PyDict::new(py);
        sd.set_item("step", s.step)?;
        sd.set_item("task_index", s.task_index)?;
        sd.set_item("sub_task", &s.sub_task)?;
        sd.set_item("action", convert::chunk(py, &s.chunk))?;
        let views: Vec<View<'_>> = s.frames.iter().map(View::from).collect();
        sd.set_item("frames", convert::frames(py, &views, history, depth)?)?;
        if let (Some(scope), Some(p)) = (how.privileged_observation, &s.privileged) {
            sd.set_item(
                "privileged_observation",
                convert::privileged_observation(py, p, scope)?,
            )?;
        }
        samples.append(sd)?;
    }
    d.set_item("samples", samples)?;
    Ok(d)
}
