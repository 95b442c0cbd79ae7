//! Contract v1.1 over real gRPC: a policy asking for `observation_history = 2` and
//! `actions_executed_per_chunk = 4` is queried every 4 steps and receives exactly two
//! consecutive frames (0.1 s apart, oldest first), each with the simulator's own hand pose and
//! the action that led to it; a v1 policy gets one frame and the organiser's execution count.

use crate::remote_support;

use std::sync::{Arc, Mutex};

use kitchen_r_contract::server::{PolicyFactory, ServeOptions};
use kitchen_r_episode::policy::{HORIZON, Policy, PolicyInput, PolicySpec};
use kitchen_r_episode::runner::{RunOptions, StepHook, run_episode};
use kitchen_r_sim::{Action, Sim, StepInfo};
use remote_support::*;

/// One frame as the policy received it: step, sim time, hand pose, previous action, images.
#[derive(Debug, Clone, PartialEq)]
struct Seen {
    step: u64,
    sim_time: f64,
    ee_pose: [f64; 7],
    previous: Option<[f64; 10]>,
    images: usize,
}

impl Seen {
    fn newest(i: &PolicyInput<'_>) -> Seen {
        Seen {
            step: i.step,
            sim_time: i.observation.time,
            ee_pose: i.ee_pose,
            previous: i.previous_action,
            images: i.observation.images.len(),
        }
    }
}

/// Per Act, the frames received, oldest first (the history, then the observation itself).
type Calls = Arc<Mutex<Vec<Vec<Seen>>>>;

/// A policy announcing `history`/`execute` that records its inputs and answers a chunk whose
/// action `i` has base velocity `i` mm/s, so the previous action names its index.
fn recording_server(history: usize, execute: Option<usize>, calls: Calls) -> TestServer {
    let factory: PolicyFactory = Arc::new(move || {
        let calls = calls.clone();
        Box::new(Scripted {
            spec: PolicySpec {
                observation_history: history,
                actions_executed_per_chunk: execute,
                ..spec(HORIZON)
            },
            answer: Arc::new(move |i: &PolicyInput<'_>| {
                let mut frames: Vec<Seen> = (i.history.iter())
                    .map(|f| Seen {
                        step: f.step,
                        sim_time: f.observation.time,
                        ee_pose: f.ee_pose,
                        previous: f.previous_action,
                        images: f.observation.images.len(),
                    })
                    .collect();
                frames.push(Seen::newest(i));
                calls.lock().unwrap().push(frames);
                Ok(chunk())
            }),
        }) as Box<dyn Policy>
    });
    TestServer::start(factory, ServeOptions::default())
}

fn chunk() -> Vec<[f64; 10]> {
    (0..HORIZON)
        .map(|i| {
            let mut a = STILL;
            a[0] = i as f64 * 1e-3;
            a
        })
        .collect()
}

/// The simulator's own view: the hand pose after every step (index = step) and the actions.
struct Truth {
    ee: Vec<[f64; 7]>,
    actions: Vec<[f64; 10]>,
}

fn pose(sim: &Sim) -> [f64; 7] {
    let ee = sim.ee_pose();
    let (t, q) = (ee.translation.vector, ee.rotation);
    [t.x, t.y, t.z, q.w, q.i, q.j, q.k]
}

impl StepHook for Truth {
    fn on_step(&mut self, sim: &Sim, action: &Action, info: &StepInfo) -> Result<(), String> {
        assert_eq!(info.step as usize, self.ee.len());
        self.ee.push(pose(sim));
        self.actions.push(action.0);
        Ok(())
    }
}

/// One 3 s task (30 control steps) of the first dev episode with the organiser's default of 8.
fn run(url: &str) -> Truth {
    let mut remote = connect(url, 30.0);
    let mut sim = sim();
    remote.set_scene(&sim.episode().scene.clone());
    let mut truth = Truth {
        ee: vec![pose(&sim)],
        actions: Vec::new(),
    };
    let opts = RunOptions {
        task_time_limit: 3.0,
        max_tasks: Some(1),
        ..RunOptions::default()
    };
    let out = run_episode(&mut sim, &mut remote, &opts, None, &mut truth).unwrap();
    let f = out.tasks[0].failure.as_deref().unwrap_or_default();
    assert!(f.starts_with("time limit of 3 s reached"), "{f}");
    truth
}

#[test]
fn a_policy_gets_the_history_and_execution_count_it_asked_for() {
    let calls = Calls::default();
    let server = recording_server(2, Some(4), calls.clone());
    let truth = run(&server.url());
    let calls = calls.lock().unwrap().clone();
    let steps: Vec<u64> = calls.iter().map(|c| c[1].step).collect();
    assert_eq!(steps, [0, 4, 8, 12, 16, 20, 24, 28], "a query every 4 steps");
    for frames in &calls {
        assert_eq!(frames.len(), 2, "exactly the frames asked for");
        let (old, new) = (&frames[0], &frames[1]);
        if new.step == 0 {
            assert_eq!(old, new, "the task's first Act: padded with its first frame");
        } else {
            assert_eq!(old.step + 1, new.step, "consecutive, oldest first");
            let dt = new.sim_time - old.sim_time;
            assert!((dt - 0.1).abs() < 1e-9, "0.1 s apart, got {dt}");
        }
        for f in frames {
            assert!((f.sim_time - f.step as f64 * 0.1).abs() < 1e-9, "{f:?}");
            assert_eq!(f.images, 2, "the default cameras in every frame");
            assert_eq!(f.ee_pose, truth.ee[f.step as usize], "the simulator's hand pose");
            let previous = f.step.checked_sub(1).map(|s| truth.actions[s as usize]);
            assert_eq!(f.previous, previous, "the action that led to step {}", f.step);
        }
        if new.step > 0 {
            // The 4th action of the last chunk (base velocity 3 mm/s) led to the query.
            assert_eq!(new.previous.unwrap()[0], 3e-3);
        }
    }
    assert!(truth.ee.windows(2).any(|w| w[0] != w[1]), "the hand moved");
}

#[test]
fn a_v1_policy_gets_one_frame_and_the_organisers_count() {
    let calls = Calls::default();
    let server = recording_server(1, None, calls.clone());
    let truth = run(&server.url());
    let calls = calls.lock().unwrap().clone();
    let steps: Vec<u64> = calls.iter().map(|c| c.last().unwrap().step).collect();
    assert_eq!(steps, [0, 8, 16, 24], "the organiser's 8 actions per chunk");
    for frames in &calls {
        assert_eq!(frames.len(), 1, "no history");
        let f = &frames[0];
        assert_eq!(
            f.ee_pose, truth.ee[f.step as usize],
            "the hand pose, unprivileged"
        );
    }
}
