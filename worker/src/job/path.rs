//! Where the robot went (its plot: docs/reference/pages.md): the base's and the key object's paths
//! of an online episode, sampled every few control steps, with each task's goal and where the task
//! ended, for the episode's top-down plot.

use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_sim::{Action, Sim, StepInfo, TaskTarget};

use kitchen_r_episode::runner::StepHook;

/// The most points a path keeps: past it, every second point is dropped and the stride doubles.
pub(crate) const MAX_POINTS: usize = 4096;
/// Goal radius of a navigation task (the approach tolerance drawn), metres.
const NAV_RADIUS: f32 = 0.10;
/// Goal radius of a place task, metres.
const PLACE_RADIUS: f32 = 0.05;

/// Samples the path while passing every call on to `inner`.
pub(crate) struct PathHook<'a> {
    inner: &'a mut dyn StepHook,
    path: pb::EpisodePath,
    stride: u64,
    seen: u64,
    task: Option<usize>,
    /// The episode object the current task is about (the last picked or placed).
    object: Option<usize>,
}

impl<'a> PathHook<'a> {
    pub(crate) fn new(inner: &'a mut dyn StepHook) -> PathHook<'a> {
        PathHook {
            inner,
            path: pb::EpisodePath::default(),
            stride: 1,
            seen: 0,
            task: None,
            object: None,
        }
    }

    pub(crate) fn into_path(self) -> pb::EpisodePath {
        self.path
    }

    fn sample(&mut self, sim: &Sim, task: usize) {
        let base = sim.base_pose();
        let obj = self
            .object
            .and_then(|o| sim.object_poses().get(o).map(|(_, p)| p.translation.vector))
            .map_or([f32::NAN; 2], |v| [v.x as f32, v.y as f32]);
        self.path.base_xy.extend([base[0] as f32, base[1] as f32]);
        self.path.object_xy.extend(obj);
        self.path.task.push(task as u32);
        if self.path.task.len() >= MAX_POINTS {
            self.thin();
        }
    }

    /// Keep every second point, and sample half as often from now on.
    fn thin(&mut self) {
        let p = &mut self.path;
        let keep = |i: usize| i.is_multiple_of(2);
        p.task = p
            .task
            .iter()
            .enumerate()
            .filter(|(i, _)| keep(*i))
            .map(|(_, t)| *t)
            .collect();
        let pairs = |v: &[f32]| -> Vec<f32> {
            v.chunks(2)
                .enumerate()
                .filter(|(i, _)| keep(*i))
                .flat_map(|(_, c)| c.iter().copied())
                .collect()
        };
        p.base_xy = pairs(&p.base_xy);
        p.object_xy = pairs(&p.object_xy);
        self.stride *= 2;
    }
}

impl StepHook for PathHook<'_> {
    fn on_step(&mut self, sim: &Sim, action: &Action, info: &StepInfo) -> Result<(), String> {
        if let Some(t) = self.task {
            if let Some(g) = self.path.goals.last_mut() {
                g.end_x = info.base_pose[0] as f32;
                g.end_y = info.base_pose[1] as f32;
            }
            if self.seen.is_multiple_of(self.stride) {
                self.sample(sim, t);
            }
            self.seen += 1;
        }
        self.inner.on_step(sim, action, info)
    }

    fn wants_observation(&self) -> bool {
        self.inner.wants_observation()
    }

    fn observation(&mut self, obs: &kitchen_r_sim::Observation) {
        self.inner.observation(obs);
    }

    fn on_task_start(&mut self, sim: &Sim, index: usize) {
        self.inner.on_task_start(sim, index);
        self.task = Some(index);
        let base = sim.base_pose();
        let (kind, xy, radius) = match kitchen_r_sim::task_target(sim.episode(), sim.scene(), index) {
            Ok(TaskTarget::Base { x, y, .. }) => ("nav", [x, y], NAV_RADIUS),
            Ok(TaskTarget::Pick { object }) => {
                self.object = Some(object);
                let p = sim.object_poses().get(object).map(|(_, p)| p.translation.vector);
                ("pick", p.map_or([f64::NAN; 2], |v| [v.x, v.y]), 0.0)
            }
            Ok(TaskTarget::Place { object, target }) => {
                self.object = Some(object);
                ("place", [target[0], target[1]], PLACE_RADIUS)
            }
            Err(_) => ("", [f64::NAN; 2], 0.0),
        };
        self.path.goals.push(pb::PathGoal {
            index: index as u32,
            kind: kind.to_string(),
            x: xy[0] as f32,
            y: xy[1] as f32,
            radius,
            end_x: base[0] as f32,
            end_y: base[1] as f32,
        });
        self.sample(sim, index);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_every_second_point_with_its_task_and_doubles_the_stride() {
        let mut inner = ();
        let mut h = PathHook::new(&mut inner);
        for i in 0..6u32 {
            h.path.base_xy.extend([i as f32, 0.0]);
            h.path.object_xy.extend([0.0, i as f32]);
            h.path.task.push(i / 3);
        }
        h.thin();
        assert_eq!(h.path.task, vec![0, 0, 1]);
        assert_eq!(h.path.base_xy, vec![0.0, 0.0, 2.0, 0.0, 4.0, 0.0]);
        assert_eq!(h.path.object_xy, vec![0.0, 0.0, 0.0, 2.0, 0.0, 4.0]);
        assert_eq!(h.stride, 2);
    }
}
