//! An episode driven one action at a time from outside: the Python environment's `step`.
//!
//! It is not a second runner. The episode runs in [`run_episode`](crate::runner::run_episode) on a
//! thread of its own, with a relay as its policy: at every decision point the relay hands the
//! decision out and waits for the next action, which it returns as a chunk that the runner executes
//! one action of (`actions_executed_per_chunk = 1`). Task starts and ends, success checks, time
//! limits, teleport on failure and the chunk rules (quaternion and gripper corrections, counted as
//! warnings) are therefore the leaderboard's own, and the same seed gives the same episode as
//! `kitchen-r eval` and the workers.
//!
//! The expert can be asked for its chunk at any decision ([`DrivenEpisode::expert_chunk`]): an
//! oracle follows the episode beside the relay and answers from privileged state. Asked at
//! every `k`-th decision with its chunk's first `k` actions executed, it drives exactly as
//! `kitchen-r eval --policy builtin:oracle` with `execute = k` does. Asked after actions it
//! did not choose (DAgger), it labels from the state it finds; its path follower and phase
//! machine carry on from what it last predicted, re-anchored on the measured pose.

use std::sync::mpsc::{Receiver, RecvError, Sender, TryRecvError, channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use kitchen_r_sim::{Action, Assets, EpisodeConfig, Observation, Sim, StepInfo};

use crate::hooks::WrapHook;
use crate::oracle::OraclePolicy;
use crate::policy::{
    ACTION_DIM, Frame, HORIZON, MAX_OBSERVATION_HISTORY, Policy, PolicyError, PolicyInput, PolicySpec,
    Privileged, check_chunk,
};
use crate::runner::{EpisodeOutcome, RunOptions, StepHook, TaskRecord, ee_pose, run_from_task};
use crate::teleport::expert_starts;

/// How a driven episode runs.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveOptions {
    /// Task time limit, plan steps, chunk tolerance (`execute`, `privileged`, budgets and
    /// timeouts do not apply: the driver executes one action per decision and is not timed).
    pub run: RunOptions,
    /// After a failed task, continue from the expert's state at the start of the next one.
    pub teleport_on_failure: bool,
    /// Render the cameras (and LiDAR) at every decision; false gives the robot state only.
    pub images: bool,
    /// Hand the cameras' depth out with each decision ([`Decision::observation`]); false leaves
    /// it (and the LiDAR scan, which no driver reads) behind on the episode's thread: less to
    /// copy at every step. What is simulated and rendered is the same either way.
    pub depth: bool,
    /// Consecutive control steps each decision shows, the newest included (1..=8).
    pub observation_history: usize,
    /// Keep the expert ready for [`DrivenEpisode::expert_chunk`].
    pub expert: bool,
    /// Ask the expert at every decision, on the episode's thread, and hand its chunk out with
    /// the decision ([`Decision::expert`]): labels for every state without a second round
    /// trip. Needs `expert`.
    pub expert_inline: bool,
    /// Run only this plan step, from the expert's state at its start (one sub-task as an
    /// episode); `None` runs the plan from its first step (up to `run.max_tasks`).
    pub only_task: Option<usize>,
    /// A live view the episode also runs with (the Python environment's `ros2=True`): a hook
    /// around the episode's own, which like every hook must not change the episode.
    pub watch: Option<WrapHook>,
}

impl Default for DriveOptions {
    fn default() -> Self {
        DriveOptions {
            run: RunOptions::default(),
            teleport_on_failure: true,
            images: true,
            depth: true,
            observation_history: 1,
            expert: true,
            expert_inline: false,
            only_task: None,
            watch: None,
        }
    }
}

/// One decision point: what a policy would be sent, plus the privileged state.
#[derive(Debug, Clone)]
pub struct Decision {
    /// Control steps since the episode started.
    pub step: u64,
    pub task_index: usize,
    pub sub_task: String,
    pub observation: Observation,
    /// Hand pose in the base frame `[x, y, z, qw, qx, qy, qz]`.
    pub ee_pose: [f64; 7],
    pub previous_action: Option<[f64; ACTION_DIM]>,
    /// Earlier frames of the task, oldest first (`observation_history - 1` at most).
    pub history: Vec<Frame>,
    /// The robot, the task's goal and the key objects in the scene frame.
    pub privileged: Privileged,
    /// The expert's chunk for this state, or why it has none ([`DriveOptions::expert_inline`]).
    pub expert: Option<Result<Vec<[f64; ACTION_DIM]>, String>>,
}

/// How the episode ended.
#[derive(Debug, Clone)]
pub struct Ended {
    pub outcome: EpisodeOutcome,
    /// The world after the last action, as a policy would have seen it.
    pub observation: Observation,
    /// Hand pose in the base frame then `[x, y, z, qw, qx, qy, qz]`.
    pub ee_pose: [f64; 7],
    /// The last action executed (`None` if none was, or the last task began with a teleport).
    pub previous_action: Option<[f64; ACTION_DIM]>,
}

/// What an action led to: the tasks that ended with it, then the next decision or the end.
#[derive(Debug, Clone)]
pub struct Progress {
    pub tasks_ended: Vec<TaskRecord>,
    pub next: Next,
}

#[derive(Debug, Clone)]
pub enum Next {
    Decision(Box<Decision>),
    Ended(Box<Ended>),
}

#[derive(Debug, thiserror::Error)]
pub enum DriveError {
    /// The action breaks the chunk rules (shape, finite values, gripper range, unit quaternion
    /// beyond the tolerance). Nothing was executed; the decision still waits for an action.
    #[error("invalid action: {0}")]
    BadAction(String),
    #[error("the episode has ended: reset it before stepping")]
    Ended,
    #[error("the expert is off for this episode (DriveOptions::expert)")]
    NoExpert,
    #[error("the expert failed: {0}")]
    Expert(String),
    /// `receive` while a decision waits for its action: nothing was sent to wait for.
    #[error("a decision is waiting for an action: send one before receiving")]
    Pending,
    /// An action is on its way and its result was not received yet.
    #[error("the last action's result was not received yet: receive it first")]
    InFlight,
    /// The simulator failed (a platform error, not the driver's).
    #[error("simulator: {0}")]
    Sim(String),
}

enum Cmd {
    Act([f64; ACTION_DIM]),
    Expert,
}

enum Event {
    TaskEnded(TaskRecord),
    Decision(Box<Decision>),
    Expert(Result<Vec<[f64; ACTION_DIM]>, String>),
    Ended(Box<Ended>),
    Failed(String),
}

/// An episode running on its own thread, waiting at a decision for [`DrivenEpisode::act`].
pub struct DrivenEpisode {
    cmds: Option<Sender<Cmd>>,
    events: Receiver<Event>,
    thread: Option<JoinHandle<Sim>>,
    tolerance: crate::policy::ChunkTolerance,
    has_expert: bool,
    /// A decision waits for its action.
    waiting: bool,
    /// The end was received: nothing more will come.
    ended: bool,
}

impl DrivenEpisode {
    /// Load `cfg` into `sim` and run it until its first decision (or its end, for an episode
    /// with no task). Teleport on failure first runs the expert over the episode once.
    pub fn start(
        sim: Sim,
        cfg: EpisodeConfig,
        assets: &Assets,
        opts: &DriveOptions,
    ) -> Result<(DrivenEpisode, Progress), DriveError> {
        let mut ep = DrivenEpisode::launch(sim, cfg, assets, opts)?;
        let first = ep.receive()?;
        Ok((ep, first))
    }

    /// [`DrivenEpisode::start`] without waiting: the episode runs towards its first decision
    /// on its thread while the caller launches others; [`DrivenEpisode::receive`] waits.
    pub fn launch(
        mut sim: Sim,
        cfg: EpisodeConfig,
        assets: &Assets,
        opts: &DriveOptions,
    ) -> Result<DrivenEpisode, DriveError> {
        let (cmd_tx, cmd_rx) = channel();
        let (ev_tx, ev_rx) = channel();
        // The expert drives the twin's own grasp mode (the Python env's `grasp_mode`).
        let grasp = sim.config().grasp.mode;
        let expert = (opts.expert).then(|| OraclePolicy::new(assets).without_images().with_grasp_mode(grasp));
        // One sub-task from a later step needs the expert's states even without teleports.
        let starts_from =
            (opts.teleport_on_failure || opts.only_task.is_some_and(|j| j > 0)).then(|| assets.clone());
        let first = opts.only_task.unwrap_or(0);
        let mut run = RunOptions {
            // Every decision carries the privileged state: the expert reads it, and the
            // environment shows it when asked. It changes nothing in the simulation.
            privileged: true,
            wall_budget: None,
            max_consecutive_timeouts: u32::MAX,
            ..opts.run.clone()
        };
        run.execute = 1;
        if let Some(j) = opts.only_task {
            run.max_tasks = Some(j + 1);
        }
        let relay = Relay {
            spec: PolicySpec {
                name: "driven".into(),
                horizon: HORIZON,
                observation_history: opts.observation_history.clamp(1, MAX_OBSERVATION_HISTORY),
                actions_executed_per_chunk: Some(1),
                ..PolicySpec::default()
            },
            images: opts.images,
            cmds: cmd_rx,
            events: ev_tx.clone(),
            inline: opts.expert_inline && expert.is_some(),
            depth: opts.depth,
            last_action: None,
            expert,
            abandoned: false,
        };
        let watch = opts.watch.clone();
        let thread = std::thread::Builder::new()
            .name("kitchen-r-driven".into())
            .spawn(move || {
                // A failure was sent as an event; the simulator comes back either way.
                let how = (&run, first, watch.as_ref());
                let _ = drive(&mut sim, &cfg, starts_from, relay, how, ev_tx);
                sim
            })
            .map_err(|e| DriveError::Sim(format!("cannot start the episode's thread: {e}")))?;
        Ok(DrivenEpisode {
            cmds: Some(cmd_tx),
            events: ev_rx,
            thread: Some(thread),
            tolerance: opts.run.chunk_tolerance,
            has_expert: opts.expert,
            waiting: false,
            ended: false,
        })
    }

    /// Execute `action` for one control step (after the chunk rules' checks).
    pub fn act(&mut self, action: [f64; ACTION_DIM]) -> Result<Progress, DriveError> {
        self.send_action(action)?;
        self.receive()
    }

    /// [`DrivenEpisode::act`] without waiting: the action is checked and handed to the
    /// episode's thread, which steps while the caller hands actions to other episodes;
    /// [`DrivenEpisode::receive`] waits for what it led to.
    pub fn send_action(&mut self, action: [f64; ACTION_DIM]) -> Result<(), DriveError> {
        self.check_action(action)?;
        self.send(Cmd::Act(action))?;
        self.waiting = false;
        Ok(())
    }

    /// The expert's chunk of 16 actions for the current decision.
    pub fn expert_chunk(&mut self) -> Result<Vec<[f64; ACTION_DIM]>, DriveError> {
        self.check_waiting()?;
        if !self.has_expert {
            return Err(DriveError::NoExpert);
        }
        self.send(Cmd::Expert)?;
        match self.events.recv() {
            Ok(Event::Expert(r)) => r.map_err(DriveError::Expert),
            Ok(Event::Failed(e)) => Err(DriveError::Sim(e)),
            Ok(_) => Err(DriveError::Sim("the episode thread answered out of turn".into())),
            Err(_) => Err(DriveError::Sim("the episode thread stopped".into())),
        }
    }

    /// Whether [`DrivenEpisode::send_action`] would take `action` now (a decision waits and the
    /// action keeps the chunk rules), without sending it: a driver of several episodes checks
    /// every action before it sends any.
    pub fn check_action(&self, action: [f64; ACTION_DIM]) -> Result<(), DriveError> {
        self.check_waiting()?;
        let mut chunk = [action; HORIZON];
        check_chunk(&mut chunk, HORIZON, &self.tolerance).map_err(|e| match e {
            PolicyError::BadChunk(m) => DriveError::BadAction(m),
            other => DriveError::BadAction(other.to_string()),
        })?;
        Ok(())
    }

    fn check_waiting(&self) -> Result<(), DriveError> {
        match (self.waiting, self.ended) {
            (true, _) => Ok(()),
            (false, true) => Err(DriveError::Ended),
            (false, false) => Err(DriveError::InFlight),
        }
    }

    /// Stop the episode (if it still runs) and hand the simulator back for the next one.
    pub fn finish(mut self) -> Option<Sim> {
        self.stop()
    }

    /// Dropping the sender makes every later decision fail at once: the runner races through
    /// the remaining tasks without stepping and returns, and the thread hands the sim back.
    fn stop(&mut self) -> Option<Sim> {
        self.cmds = None;
        while self.events.recv().is_ok() {}
        self.thread.take().and_then(|t| t.join().ok())
    }

    fn send(&mut self, cmd: Cmd) -> Result<(), DriveError> {
        let sent = self.cmds.as_ref().map(|c| c.send(cmd));
        match sent {
            Some(Ok(())) => Ok(()),
            _ => Err(DriveError::Sim("the episode thread stopped".into())),
        }
    }

    /// Events up to the next decision or the end: what the launch or the last action sent led
    /// to. Called again while a decision waits, it reports nothing new ([`DriveError::Ended`]
    /// after the end). The caller's thread waits awake for up to [`DRIVER_SPIN`]: for a driver
    /// of one episode.
    pub fn receive(&mut self) -> Result<Progress, DriveError> {
        self.receive_within(DRIVER_SPIN)
    }

    /// [`DrivenEpisode::receive`] for a driver of several episodes on fewer cores (the vector
    /// env): it sleeps at once and leaves the cores to the episodes.
    pub fn receive_sleeping(&mut self) -> Result<Progress, DriveError> {
        self.receive_within(Duration::ZERO)
    }

    fn receive_within(&mut self, spin: Duration) -> Result<Progress, DriveError> {
        if self.waiting {
            return Err(DriveError::Pending);
        }
        if self.ended {
            return Err(DriveError::Ended);
        }
        let mut tasks_ended = Vec::new();
        loop {
            match recv_soon(&self.events, spin) {
                Ok(Event::TaskEnded(t)) => tasks_ended.push(t),
                Ok(Event::Decision(d)) => {
                    self.waiting = true;
                    return Ok(Progress {
                        tasks_ended,
                        next: Next::Decision(d),
                    });
                }
                Ok(Event::Ended(e)) => {
                    self.ended = true;
                    return Ok(Progress {
                        tasks_ended,
                        next: Next::Ended(e),
                    });
                }
                Ok(Event::Failed(e)) => {
                    self.ended = true;
                    return Err(DriveError::Sim(e));
                }
                Ok(Event::Expert(_)) => {}
                Err(_) => {
                    self.ended = true;
                    return Err(DriveError::Sim("the episode thread stopped".into()));
                }
            }
        }
    }
}

impl Drop for DrivenEpisode {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The episode thread's body: the leaderboard's runner, with the relay as its policy.
fn drive(
    sim: &mut Sim,
    cfg: &EpisodeConfig,
    starts_from: Option<Assets>,
    mut relay: Relay,
    (run, first, watch): (&RunOptions, usize, Option<&WrapHook>),
    events: Sender<Event>,
) -> Result<(), ()> {
    let fail = |e: String| {
        let _ = events.send(Event::Failed(e));
    };
    if let Err(e) = sim.reset(cfg) {
        fail(e.to_string());
        return Err(());
    }
    let starts = match starts_from {
        Some(assets) => match expert_starts(sim, cfg, &assets) {
            Ok(s) => Some(s),
            Err(e) => {
                fail(e.to_string());
                return Err(());
            }
        },
        None => None,
    };
    let mut hook = TaskEnds(events.clone());
    let ran = WrapHook::around(watch, &mut hook, |h| {
        run_from_task(sim, &mut relay, run, starts.as_deref(), h, first)
    });
    let outcome = match ran {
        Ok(o) => o,
        Err(e) => {
            fail(e.to_string());
            return Err(());
        }
    };
    let observation = if relay.images {
        sim.observe()
    } else {
        sim.observe_state()
    };
    // The last action as the runner executed it, corrections applied (once, here, rather
    // than for every action on the way).
    let previous_action = relay.last_action.map(|a| {
        let mut executed = [a];
        let _ = check_chunk(&mut executed, 1, &run.chunk_tolerance);
        executed[0]
    });
    let _ = events.send(Event::Ended(Box::new(Ended {
        outcome,
        observation,
        ee_pose: ee_pose(sim),
        previous_action,
    })));
    Ok(())
}

/// Tells the driver each task's end as it happens.
struct TaskEnds(Sender<Event>);

impl StepHook for TaskEnds {
    fn on_step(&mut self, _: &Sim, _: &Action, _: &StepInfo) -> Result<(), String> {
        Ok(())
    }
    fn on_task_end(&mut self, _: &Sim, task: &TaskRecord) {
        let _ = self.0.send(Event::TaskEnded(task.clone()));
    }
}

/// The runner's policy: hands each decision to the driver and returns its action.
struct Relay {
    spec: PolicySpec,
    images: bool,
    cmds: Receiver<Cmd>,
    events: Sender<Event>,
    expert: Option<OraclePolicy>,
    /// Ask `expert` at every decision and send its chunk with it.
    inline: bool,
    /// Decisions carry depth and LiDAR ([`DriveOptions::depth`]).
    depth: bool,
    /// The previous action of the decision last handed out, then the action that answered it.
    last_action: Option<[f64; ACTION_DIM]>,
    /// The driver is gone: every decision fails at once so the runner ends quickly.
    abandoned: bool,
}

const ABANDONED: &str = "the episode was abandoned by its driver";

impl Policy for Relay {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }

    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        if let Some(e) = &mut self.expert {
            e.reset(episode_id, task_index, sub_task)?;
        }
        Ok(())
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        if self.abandoned {
            return Err(PolicyError::Call(ABANDONED.into()));
        }
        let Some(privileged) = input.privileged.cloned() else {
            return Err(PolicyError::NeedsPrivileged);
        };
        let expert = match (&mut self.expert, self.inline) {
            // The expert's failure is reported, never the episode's: it changes nothing.
            (Some(e), true) => Some(e.act(input).map_err(|e| e.to_string())),
            _ => None,
        };
        self.last_action = input.previous_action;
        let decision = Decision {
            expert,
            step: input.step,
            task_index: input.task_index,
            sub_task: input.sub_task.to_string(),
            observation: handed_out(input.observation, self.depth),
            ee_pose: input.ee_pose,
            previous_action: input.previous_action,
            history: input.history.to_vec(),
            privileged,
        };
        if self.events.send(Event::Decision(Box::new(decision))).is_err() {
            self.abandoned = true;
            return Err(PolicyError::Call(ABANDONED.into()));
        }
        loop {
            match recv_soon(&self.cmds, SPIN) {
                Ok(Cmd::Act(a)) => {
                    self.last_action = Some(a);
                    return Ok(vec![a; HORIZON]);
                }
                Ok(Cmd::Expert) => {
                    let chunk = match &mut self.expert {
                        Some(e) => e.act(input).map_err(|e| e.to_string()),
                        None => Err(DriveError::NoExpert.to_string()),
                    };
                    if self.events.send(Event::Expert(chunk)).is_err() {
                        self.abandoned = true;
                        return Err(PolicyError::Call(ABANDONED.into()));
                    }
                }
                Err(_) => {
                    self.abandoned = true;
                    return Err(PolicyError::Call(ABANDONED.into()));
                }
            }
        }
    }

    fn wants_images(&self) -> bool {
        self.images
    }
}

/// The observation a decision carries: all of it, or without depth and LiDAR.
fn handed_out(o: &Observation, depth: bool) -> Observation {
    if depth {
        return o.clone();
    }
    let images = (o.images.iter())
        .map(|im| kitchen_r_sim::sensors::CameraImage {
            name: im.name.clone(),
            width: im.width,
            height: im.height,
            rgb: im.rgb.clone(),
            depth: Vec::new(),
        })
        .collect();
    Observation {
        time: o.time,
        images,
        lidar: None,
        odometry: o.odometry,
        joints: o.joints,
        gripper: o.gripper,
        task: o.task.clone(),
    }
}

/// How long the episode's thread waits for the driver's answer awake before it sleeps.
const SPIN: Duration = Duration::from_millis(1);

/// How long the driver waits awake for the episode's next decision before it sleeps: a control
/// step (simulation, cameras, the expert) takes a few milliseconds, and a driver woken from
/// sleep after each one added about 0.2 ms a step on a virtual machine, the binding's overhead
/// over the Rust runner. Yielding between polls gives the core to any thread that needs it (the
/// vector env's episodes on a machine with fewer cores than environments).
const DRIVER_SPIN: Duration = Duration::from_millis(10);

/// Receive from `rx`, polling for up to `spin` (yielding the core between polls) before sleeping.
/// Each side answers the other within milliseconds (the driver converts a decision and hands back
/// an action within a fraction of one, [`SPIN`]; a control step takes a few, [`DRIVER_SPIN`]), and
/// waking a sleeping thread costs about as much on a virtual machine. Timing only: what is
/// received is the same.
fn recv_soon<T>(rx: &Receiver<T>, spin: Duration) -> Result<T, RecvError> {
    let started = Instant::now();
    loop {
        match rx.try_recv() {
            Ok(v) => return Ok(v),
            Err(TryRecvError::Disconnected) => return Err(RecvError),
            Err(TryRecvError::Empty) if started.elapsed() < spin => std::thread::yield_now(),
            Err(TryRecvError::Empty) => return rx.recv(),
        }
    }
}
