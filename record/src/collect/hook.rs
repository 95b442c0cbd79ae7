//! The step hook that records an expert episode and runs the Monitoring Module's checks after
//! every control step: the first monitor that trips stops the episode with its reason.

use kitchen_r_sim::config::MonitorConfig;
use kitchen_r_sim::task::MonitorTrip;
use kitchen_r_sim::{Action, Observation, Sim, StepInfo};

use crate::frame::frame_of;
use crate::hdf5_aloha::Hdf5Recorder;
use crate::lerobot::EpisodeRecorder;
use crate::mcap_ros2::McapRecorder;
use crate::rate::RateMonitor;
use crate::{Frame, TaskSpan};
use kitchen_r_episode::runner::StepHook;

/// Why an episode was discarded, as counted in the summary.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct Trip {
    /// Short reason key (`time_limit`, `object_on_floor`, ...).
    pub kind: String,
    pub message: String,
}

impl Trip {
    pub(super) fn new(kind: &str, message: impl Into<String>) -> Trip {
        Trip {
            kind: kind.to_string(),
            message: message.into(),
        }
    }

    fn monitor(m: &MonitorTrip) -> Trip {
        let (kind, msg) = match m {
            MonitorTrip::TimeLimit { limit } => ("time_limit", format!("action over its {limit} s limit")),
            MonitorTrip::ObjectOnFloor { object } => {
                ("object_on_floor", format!("{object} fell to the floor"))
            }
            MonitorTrip::GripperFarFromObject { distance } => (
                "gripper_far_from_object",
                format!("gripper {distance:.3} m from the object after pick"),
            ),
            MonitorTrip::ObjectFarFromGoal { distance } => (
                "object_far_from_goal",
                format!("object {distance:.3} m from the goal after place"),
            ),
            MonitorTrip::RobotOutsideGoal { distance } => (
                "robot_outside_goal",
                format!("base {distance:.3} m from the goal after move"),
            ),
        };
        Trip::new(kind, msg)
    }
}

pub(super) struct Recorder {
    pub mcap: Option<McapRecorder>,
    pub hdf5: Option<Hdf5Recorder>,
    pub lerobot: Option<EpisodeRecorder>,
    /// Keep depth images (`collect --no-depth` drops them before any writer sees them).
    pub depth: bool,
    pub rate: RateMonitor,
    pub monitors: MonitorConfig,
    pub spans: Vec<TaskSpan>,
    pub frames: usize,
    pub trip: Option<Trip>,
    /// Task index and first frame of the running task.
    current: Option<(usize, usize, f64)>,
    /// This step's observation, rendered once by the runner (see `StepHook::observation`).
    latest: Option<Observation>,
}

impl Recorder {
    pub(super) fn new(
        mcap: Option<McapRecorder>,
        hdf5: Option<Hdf5Recorder>,
        lerobot: Option<EpisodeRecorder>,
        rate: RateMonitor,
        monitors: MonitorConfig,
    ) -> Recorder {
        Recorder {
            mcap,
            hdf5,
            lerobot,
            depth: true,
            rate,
            monitors,
            spans: Vec::new(),
            frames: 0,
            trip: None,
            current: None,
            latest: None,
        }
    }

    fn frame(&mut self, sim: &Sim, action: &Action, info: &StepInfo, task: usize) -> Frame {
        let obs = self.latest.take().unwrap_or_else(|| sim.observe());
        frame_of(sim, obs, action, info, task, self.depth)
    }

    fn record(&mut self, sim: &Sim, action: &Action, info: &StepInfo, task: usize) -> Result<(), Trip> {
        let frame = self.frame(sim, action, info, task);
        if let Some(m) = &mut self.mcap {
            m.write_frame(&frame, Some(&mut self.rate))
                .map_err(|e| Trip::new("write_error", e.to_string()))?;
        } else {
            for topic in ["/odom", "/tf", "/action", "/lidar/points"] {
                self.rate.record(topic, frame.time);
            }
            for c in &frame.cameras {
                self.rate
                    .record(&format!("/camera/{}/image_raw", c.name), frame.time);
            }
        }
        if let Some(l) = &mut self.lerobot {
            l.push(&frame)
                .map_err(|e| Trip::new("write_error", e.to_string()))?;
        }
        if let Some(h) = &mut self.hdf5 {
            h.push(frame)
                .map_err(|e| Trip::new("write_error", e.to_string()))?;
        }
        self.frames += 1;
        self.rate
            .check(info.time)
            .map_err(|v| Trip::new("recording_rate", v.to_string()))
    }

    fn check(&mut self, sim: &Sim, action: &Action, info: &StepInfo) -> Result<(), Trip> {
        let Some(status) = &info.task else {
            return Err(Trip::new("no_task", "a step ran outside any task"));
        };
        if self.current.is_none_or(|c| c.0 != status.index) {
            self.current = Some((status.index, self.frames, info.time - 0.1));
        }
        self.record(sim, action, info, status.index)?;
        if let Some(m) = info.monitors.first() {
            return Err(Trip::monitor(m));
        }
        // The collection's own limits (the sim judges the task with its configured ones).
        let limit = match status.step.split(' ').next() {
            Some("move") => self.monitors.move_time_limit,
            Some("pick") => self.monitors.pick_time_limit,
            _ => self.monitors.place_time_limit,
        };
        if !status.success && status.elapsed > limit {
            return Err(Trip::monitor(&MonitorTrip::TimeLimit { limit }));
        }
        if status.success {
            let facts = sim.facts();
            if let Some(trip) = sim
                .current_task()
                .and_then(|t| t.end_checks(&self.monitors, &facts))
            {
                return Err(Trip::monitor(&trip));
            }
            let (index, start, t0) = self.current.take().unwrap_or((status.index, 0, 0.0));
            self.spans.push(TaskSpan {
                step: sim.episode().plan.get(index).cloned().unwrap_or_default(),
                start,
                end: self.frames,
                success: true,
                duration: info.time - t0,
            });
        }
        Ok(())
    }
}

impl StepHook for Recorder {
    fn wants_observation(&self) -> bool {
        true
    }

    fn observation(&mut self, obs: &Observation) {
        self.latest = Some(obs.clone());
    }

    fn on_step(&mut self, sim: &Sim, action: &Action, info: &StepInfo) -> Result<(), String> {
        self.check(sim, action, info).map_err(|t| {
            let msg = format!("{}: {}", t.kind, t.message);
            self.trip = Some(t);
            msg
        })
    }
}
