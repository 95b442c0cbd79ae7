//! Episode values as plain Python values (dicts, lists, bytes); `gym_kitchen_r/env.py` turns them
//! into numpy arrays without another copy of the images.

use kitchen_r_episode::driven::{Decision, Next, Progress};
use kitchen_r_episode::policy::Privileged;
use kitchen_r_episode::runner::TaskRecord;
use kitchen_r_sim::{Observation, TaskTarget};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

/// `{"tasks_ended": [...], "decision": {...} | None, "ended": {...} | None}`.
pub(crate) fn progress<'py>(
    py: Python<'py>,
    p: &Progress,
    depth: bool,
    privileged: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let tasks = PyList::empty(py);
    for t in &p.tasks_ended {
        tasks.append(task(py, t)?)?;
    }
    d.set_item("tasks_ended", tasks)?;
    match &p.next {
        Next::Decision(dec) => {
            d.set_item("decision", decision(py, dec, depth, privileged)?)?;
            d.set_item("ended", py.None())?;
        }
        Next::Ended(end) => {
            d.set_item("decision", py.None())?;
            let e = PyDict::new(py);
            let all = PyList::empty(py);
            for t in &end.outcome.tasks {
                all.append(task(py, t)?)?;
            }
            e.set_item("tasks", all)?;
            e.set_item("sim_time", end.outcome.sim_time)?;
            e.set_item("success_rate", end.outcome.success_rate())?;
            e.set_item("observation", observation(py, &end.observation, depth)?)?;
            d.set_item("ended", e)?;
        }
    }
    Ok(d)
}

fn task<'py>(py: Python<'py>, t: &TaskRecord) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("index", t.index)?;
    d.set_item("step", &t.step)?;
    d.set_item("success", t.success)?;
    d.set_item("sim_time", t.sim_time)?;
    d.set_item("failure", t.failure.as_deref())?;
    d.set_item("aborts_episode", t.aborts_episode)?;
    Ok(d)
}

fn decision<'py>(
    py: Python<'py>,
    dec: &Decision,
    depth: bool,
    with_privileged: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("step", dec.step)?;
    d.set_item("task_index", dec.task_index)?;
    d.set_item("sub_task", &dec.sub_task)?;
    d.set_item("observation", observation(py, &dec.observation, depth)?)?;
    d.set_item("ee_pose", dec.ee_pose.to_vec())?;
    d.set_item("previous_action", dec.previous_action.map(|a| a.to_vec()))?;
    let history = PyList::empty(py);
    for f in &dec.history {
        let h = observation(py, &f.observation, depth)?;
        h.set_item("ee_pose", f.ee_pose.to_vec())?;
        h.set_item("previous_action", f.previous_action.map(|a| a.to_vec()))?;
        h.set_item("step", f.step)?;
        history.append(h)?;
    }
    d.set_item("history", history)?;
    if with_privileged {
        d.set_item("privileged", privileged(py, &dec.privileged)?)?;
    }
    match &dec.expert {
        Some(Ok(chunk)) => {
            let flat: Vec<f64> = chunk.iter().flatten().copied().collect();
            d.set_item("expert", (chunk.len(), PyBytes::new(py, &f64_bytes(&flat))))?;
        }
        Some(Err(e)) => d.set_item("expert_error", e)?,
        None => {}
    }
    Ok(d)
}

fn observation<'py>(py: Python<'py>, o: &Observation, depth: bool) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("time", o.time)?;
    let images = PyDict::new(py);
    let depths = PyDict::new(py);
    for im in &o.images {
        images.set_item(&im.name, (im.height, im.width, PyBytes::new(py, &im.rgb)))?;
        if depth {
            let raw: Vec<u8> = im.depth.iter().flat_map(|v| v.to_ne_bytes()).collect();
            depths.set_item(&im.name, (im.height, im.width, PyBytes::new(py, &raw)))?;
        }
    }
    d.set_item("images", images)?;
    d.set_item("depth", depths)?;
    d.set_item("odometry", o.odometry.pose.to_vec())?;
    d.set_item("velocity", o.odometry.velocity.to_vec())?;
    d.set_item("joints", o.joints.to_vec())?;
    d.set_item("gripper", o.gripper)?;
    Ok(d)
}

fn privileged<'py>(py: Python<'py>, p: &Privileged) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("scene", &p.scene)?;
    d.set_item("base_pose", p.base_pose.to_vec())?;
    d.set_item("held", p.held.as_deref())?;
    let target = PyDict::new(py);
    match &p.target {
        TaskTarget::Base { x, y, yaw } => {
            target.set_item("kind", "move")?;
            target.set_item("pose", vec![*x, *y, *yaw])?;
        }
        TaskTarget::Pick { object } => {
            target.set_item("kind", "pick")?;
            target.set_item("object", p.objects.get(*object).map(|o| o.name.as_str()))?;
        }
        TaskTarget::Place { object, target: at } => {
            target.set_item("kind", "place")?;
            target.set_item("object", p.objects.get(*object).map(|o| o.name.as_str()))?;
            target.set_item("position", at.to_vec())?;
        }
    }
    d.set_item("target", target)?;
    let objects = PyList::empty(py);
    for o in &p.objects {
        let od = PyDict::new(py);
        od.set_item("name", &o.name)?;
        od.set_item("model", &o.model)?;
        od.set_item("pose", o.pose.to_vec())?;
        objects.append(od)?;
    }
    d.set_item("objects", objects)?;
    Ok(d)
}

/// Values as the bytes numpy reads with `frombuffer(..., float64)` (native order).
fn f64_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_ne_bytes()).collect()
}
