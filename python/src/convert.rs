//! Episode values as plain Python values (dicts, lists, bytes) that `gym_kitchen_r` turns into
//! numpy arrays without another copy: an observation history is stacked here, frame by frame,
//! into one bytes object per camera and one for the robot state.

use kitchen_r_core::observations::PrivilegedScope;
use kitchen_r_episode::driven::{Decision, Next, Progress};
use kitchen_r_episode::policy::{
    ACTION_DIM, Frame, Goal, Privileged, PrivilegedObject, PrivilegedObservation, state_vector,
};
use kitchen_r_episode::runner::TaskRecord;
use kitchen_r_sim::sensors::CameraImage;
use kitchen_r_sim::{Observation, TaskTarget};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};

/// The robot state of a frame (`gym_kitchen_r.STATE_FIELDS`): the standard state vector.
pub(crate) use kitchen_r_episode::policy::STATE_FIELDS;

/// One frame as the conversion reads it.
#[derive(Clone, Copy)]
pub(crate) struct View<'a> {
    pub(crate) observation: &'a Observation,
    pub(crate) ee_pose: &'a [f64; 7],
    pub(crate) previous_action: Option<&'a [f64; ACTION_DIM]>,
}

impl<'a> From<&'a Frame> for View<'a> {
    fn from(f: &'a Frame) -> View<'a> {
        View {
            observation: &f.observation,
            ee_pose: &f.ee_pose,
            previous_action: f.previous_action.as_ref(),
        }
    }
}

fn state(v: &View<'_>, out: &mut Vec<f64>) {
    state_vector(v.observation, v.ee_pose, v.previous_action, out);
}

/// `{"images": {camera: (n, H, W, rgb bytes)}, "depth": {camera: (n, H, W, f32 bytes)},
/// "state": (n, f64 bytes)}` for the last `history` of `frames` (oldest first), the oldest
/// repeated in front when there are fewer, as the policy contract pads a history. A camera is
/// present only when every frame has its image (the runner renders only what is shown).
pub(crate) fn frames<'py>(
    py: Python<'py>,
    frames: &[View<'_>],
    history: usize,
    depth: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let Some(first) = frames.first() else {
        return Ok(d);
    };
    let shown = &frames[frames.len().saturating_sub(history)..];
    let padded: Vec<&View<'_>> = std::iter::repeat_n(first, history.saturating_sub(shown.len()))
        .chain(shown)
        .collect();
    let n = padded.len();
    let images = PyDict::new(py);
    let depths = PyDict::new(py);
    let newest = padded[n - 1].observation;
    for (c, cam) in newest.images.iter().enumerate() {
        fn of<'a>(v: &View<'a>, c: usize, name: &str) -> Option<&'a CameraImage> {
            v.observation.images.get(c).filter(|i| i.name == name)
        }
        if !(padded.iter()).all(|v| of(v, c, &cam.name).is_some_and(|i| !i.rgb.is_empty())) {
            continue;
        }
        let shown: Vec<&CameraImage> = padded.iter().filter_map(|v| of(v, c, &cam.name)).collect();
        // Written straight into the Python bytes: one copy of each frame, not two.
        let rgb = PyBytes::new_with(py, shown.iter().map(|im| im.rgb.len()).sum(), |out| {
            let mut at = 0;
            for im in &shown {
                out[at..at + im.rgb.len()].copy_from_slice(&im.rgb);
                at += im.rgb.len();
            }
            Ok(())
        })?;
        images.set_item(&cam.name, (n, cam.height, cam.width, rgb))?;
        if depth {
            let z = PyBytes::new_with(py, shown.iter().map(|im| im.depth.len() * 4).sum(), |out| {
                for (b, v) in out.chunks_exact_mut(4).zip(shown.iter().flat_map(|im| &im.depth)) {
                    b.copy_from_slice(&v.to_ne_bytes());
                }
                Ok(())
            })?;
            depths.set_item(&cam.name, (n, cam.height, cam.width, z))?;
        }
    }
    let mut s = Vec::with_capacity(n * STATE_FIELDS.len());
    for v in &padded {
        state(v, &mut s);
    }
    d.set_item("images", images)?;
    d.set_item("depth", depths)?;
    d.set_item("state", (n, PyBytes::new(py, &f64_bytes(&s))))?;
    d.set_item("time", newest.time)?;
    Ok(d)
}

/// `{"tasks_ended": [...], "decision": {...} | None, "ended": {...} | None}`.
/// What a decision carries besides the observation.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Show {
    /// The full reference world state (`privileged=True`).
    pub(crate) privileged: bool,
    /// The privileged track's observation, with the split's scope.
    pub(crate) privileged_observation: Option<PrivilegedScope>,
}

pub(crate) fn progress<'py>(
    py: Python<'py>,
    p: &Progress,
    history: usize,
    depth: bool,
    show: &Show,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let tasks = PyList::empty(py);
    for t in &p.tasks_ended {
        tasks.append(task(py, t)?)?;
    }
    d.set_item("tasks_ended", tasks)?;
    match &p.next {
        Next::Decision(dec) => {
            d.set_item("decision", decision(py, dec, history, depth, show)?)?;
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
            let last = View {
                observation: &end.observation,
                ee_pose: &end.ee_pose,
                previous_action: end.previous_action.as_ref(),
            };
            e.set_item("frames", frames(py, &[last], history, depth)?)?;
            d.set_item("ended", e)?;
        }
    }
    Ok(d)
}

pub(crate) fn task<'py>(py: Python<'py>, t: &TaskRecord) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("index", t.index)?;
    d.set_item("step", &t.step)?;
    d.set_item("success", t.success)?;
    d.set_item("sim_time", t.sim_time)?;
    d.set_item("failure", t.failure.as_deref())?;
    d.set_item("aborts_episode", t.aborts_episode)?;
    Ok(d)
}

/// A chunk as `(actions, f64 bytes)`.
pub(crate) fn chunk<'py>(py: Python<'py>, chunk: &[[f64; ACTION_DIM]]) -> (usize, Bound<'py, PyBytes>) {
    let flat: Vec<f64> = chunk.iter().flatten().copied().collect();
    (chunk.len(), PyBytes::new(py, &f64_bytes(&flat)))
}

fn decision<'py>(
    py: Python<'py>,
    dec: &Decision,
    history: usize,
    depth: bool,
    show: &Show,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("step", dec.step)?;
    d.set_item("task_index", dec.task_index)?;
    d.set_item("sub_task", &dec.sub_task)?;
    let mut views: Vec<View<'_>> = dec.history.iter().map(View::from).collect();
    views.push(View {
        observation: &dec.observation,
        ee_pose: &dec.ee_pose,
        previous_action: dec.previous_action.as_ref(),
    });
    d.set_item("frames", frames(py, &views, history, depth)?)?;
    if show.privileged {
        d.set_item("privileged", privileged(py, &dec.privileged)?)?;
    }
    if let Some(scope) = show.privileged_observation {
        d.set_item(
            "privileged_observation",
            privileged_observation(py, &dec.privileged, scope)?,
        )?;
    }
    match &dec.expert {
        Some(Ok(c)) => d.set_item("expert", chunk(py, c))?,
        Some(Err(e)) => d.set_item("expert_error", e)?,
        None => {}
    }
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
    d.set_item("objects", objects(py, &p.objects)?)?;
    Ok(d)
}

/// Values as the bytes numpy reads with `frombuffer(..., float64)` (native order).
fn f64_bytes(values: &[f64]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_ne_bytes()).collect()
}

/// The privileged track's observation of `p` (what a policy that asked for it is sent on a
/// split of `scope`): `{"base_pose", "goal": {"kind", ...}, "objects"}`, goal in the robot frame.
pub(crate) fn privileged_observation<'py>(
    py: Python<'py>,
    p: &Privileged,
    scope: PrivilegedScope,
) -> PyResult<Bound<'py, PyAny>> {
    let Some(o) = PrivilegedObservation::from_world(p, scope) else {
        return Ok(py.None().into_bound(py));
    };
    let d = PyDict::new(py);
    d.set_item("base_pose", o.base_pose.to_vec())?;
    let goal = PyDict::new(py);
    match &o.goal {
        Goal::Approach { x, y, yaw } => {
            goal.set_item("kind", "move")?;
            goal.set_item("pose", vec![*x, *y, *yaw])?;
        }
        Goal::Pick { object, pose } => {
            goal.set_item("kind", "pick")?;
            goal.set_item("object", object)?;
            goal.set_item("pose", pose.to_vec())?;
        }
        Goal::Place { object, target } => {
            goal.set_item("kind", "place")?;
            goal.set_item("object", object)?;
            goal.set_item("position", target.to_vec())?;
        }
    }
    d.set_item("goal", goal)?;
    d.set_item("objects", objects(py, &o.objects)?)?;
    Ok(d.into_any())
}

/// Key objects as `[{"name", "model", "pose"}]` (scene frame).
fn objects<'py>(py: Python<'py>, objects: &[PrivilegedObject]) -> PyResult<Bound<'py, PyList>> {
    let list = PyList::empty(py);
    for o in objects {
        let od = PyDict::new(py);
        od.set_item("name", &o.name)?;
        od.set_item("model", &o.model)?;
        od.set_item("pose", o.pose.to_vec())?;
        list.append(od)?;
    }
    Ok(list)
}
