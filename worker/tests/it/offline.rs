//! Offline MSE: the definition checked against an independent computation from the expert's
//! recorded actions, the oracle served over gRPC scoring (almost) zero against the expert it
//! is, failed predictions charged the documented penalty, and bit-identical reruns.

use crate::remote_support;

use std::sync::Arc;

use kitchen_r_contract::server::{PolicyFactory, ServeOptions};
use kitchen_r_episode::offline::{FAILED_PREDICTION_MSE, OfflineOptions, OfflineOutcome, run_offline};
use kitchen_r_episode::oracle::{OraclePolicy, expert_options};
use kitchen_r_episode::policy::{HORIZON, Policy};
use kitchen_r_episode::runner::{RunOptions, StepHook, run_episode};
use kitchen_r_sim::{Action, Assets, Sim, StepInfo};
use remote_support::*;

const TASKS: usize = 2;

fn opts() -> OfflineOptions {
    OfflineOptions {
        max_tasks: Some(TASKS),
        ..OfflineOptions::from_run(&RunOptions::default())
    }
}

fn offline(policy: &mut dyn Policy, opts: &OfflineOptions) -> OfflineOutcome {
    let assets = Assets::load_default().unwrap();
    let mut expert = OraclePolicy::new(&assets);
    let mut s = sim();
    run_offline(&mut s, &mut expert, policy, opts, &mut ()).unwrap()
}

/// The expert's executed actions, per task.
#[derive(Default)]
struct Record(Vec<Vec<[f64; 10]>>);

impl StepHook for Record {
    fn on_step(&mut self, _: &Sim, a: &Action, _: &StepInfo) -> Result<(), String> {
        self.0.last_mut().unwrap().push(a.0);
        Ok(())
    }
    fn on_task_start(&mut self, _: &Sim, _: usize) {
        self.0.push(Vec::new());
    }
}

#[test]
fn a_constant_chunk_scores_its_hand_computed_mse() {
    // The definition, computed independently: windows start every k = 8 expert steps of a task
    // and hold the next (up to) 16 executed actions of that task.
    let mut expert = OraclePolicy::new(&Assets::load_default().unwrap());
    let mut rec = Record::default();
    let run = RunOptions {
        max_tasks: Some(TASKS),
        ..expert_options()
    };
    run_episode(&mut sim(), &mut expert, &run, None, &mut rec).unwrap();
    let expected: Vec<(f64, u32)> = rec
        .0
        .iter()
        .map(|actions| {
            let starts: Vec<usize> = (0..actions.len()).step_by(8).collect();
            let sum: f64 = starts
                .iter()
                .map(|&s| {
                    let w = &actions[s..(s + HORIZON).min(actions.len())];
                    let sq: f64 = w
                        .iter()
                        .flat_map(|a| a.iter().zip(STILL.iter()))
                        .map(|(e, p)| (f64::from(*p as f32) - f64::from(*e as f32)).powi(2))
                        .sum();
                    sq / (w.len() * 10) as f64
                })
                .sum();
            (sum / starts.len() as f64, starts.len() as u32)
        })
        .collect();

    let mut still = Scripted {
        spec: spec(HORIZON),
        answer: Arc::new(|_| Ok(vec![STILL; HORIZON])),
    };
    let out = offline(&mut still, &opts());
    assert_eq!(out.tasks.len(), TASKS);
    for (t, (mse, n)) in out.tasks.iter().zip(&expected) {
        assert_eq!(t.samples, *n, "{t:?}");
        assert!(t.mse > 0.0 && (t.mse - mse).abs() < 1e-12, "{} vs {mse}", t.mse);
        assert_eq!((t.failed, &t.failure), (0, &None));
    }
    assert_eq!(out.policy_calls, expected.iter().map(|e| e.1).sum::<u32>());

    // Same seed, same bits.
    let again = offline(&mut still, &opts());
    for (a, b) in out.tasks.iter().zip(&again.tasks) {
        assert_eq!(a.mse.to_bits(), b.mse.to_bits());
        assert_eq!(a.samples, b.samples);
    }

    // Sampling every other decision point halves the queries (rounded up per task).
    let half = offline(
        &mut still,
        &OfflineOptions {
            sample_every: 2,
            ..opts()
        },
    );
    for (t, (_, n)) in half.tasks.iter().zip(&expected) {
        assert_eq!(t.samples, n.div_ceil(2));
    }
}

#[test]
fn the_oracle_over_grpc_predicts_the_expert_almost_exactly() {
    let assets = Arc::new(Assets::load_default().unwrap());
    let a = assets.clone();
    let f: PolicyFactory = Arc::new(move || Box::new(OraclePolicy::new(&a)) as Box<dyn Policy>);
    let server = TestServer::start(f, ServeOptions::default());
    let mut remote = connect(&server.url(), 30.0);
    remote.set_scene(&sim().episode().scene.clone());
    let out = offline(
        &mut remote,
        &OfflineOptions {
            privileged: true,
            ..opts()
        },
    );
    // Not exactly 0: the queried oracle predicts 16 steps open-loop from its model of the base,
    // while the expert re-plans from the measured state at every step.
    let mse = out.mse().unwrap();
    assert!(
        out.tasks.iter().all(|t| t.failed == 0 && t.samples > 0),
        "{out:?}"
    );
    eprintln!(
        "oracle over gRPC vs expert: MSE {mse:e} over {} samples",
        out.tasks.iter().map(|t| t.samples).sum::<u32>()
    );
    assert!(mse < 1e-3, "oracle vs expert MSE {mse}");
    let mut still = Scripted {
        spec: spec(HORIZON),
        answer: Arc::new(|_| Ok(vec![STILL; HORIZON])),
    };
    let still_mse = offline(&mut still, &opts()).mse().unwrap();
    eprintln!("standing still vs expert: MSE {still_mse}");
    assert!(still_mse > 100.0 * mse.max(1e-9), "{still_mse} vs {mse}");
}

#[test]
fn failed_predictions_cost_the_penalty_and_say_why() {
    let mut nan = Scripted {
        spec: spec(HORIZON),
        answer: Arc::new(|i| {
            let mut c = vec![STILL; HORIZON];
            if i.step % 16 == 0 {
                c[2][4] = f64::NAN;
            }
            Ok(c)
        }),
    };
    let out = offline(&mut nan, &opts());
    let t = &out.tasks[0];
    assert!(t.failed > 0 && t.failed < t.samples, "{t:?}");
    let f = t.failure.as_deref().unwrap();
    assert!(
        f.contains("predictions failed") && f.contains("not finite"),
        "{f}"
    );
    // Finite in f64 but not in f32, where the comparison happens: capped at the penalty.
    let mut huge = Scripted {
        spec: spec(HORIZON),
        answer: Arc::new(|_| {
            let mut c = vec![STILL; HORIZON];
            c[0][2] = 1e39;
            Ok(c)
        }),
    };
    let out = offline(&mut huge, &opts());
    assert!(
        out.tasks
            .iter()
            .all(|t| t.mse == FAILED_PREDICTION_MSE && t.failed == 0),
        "{out:?}"
    );
    let mut short = Scripted {
        spec: spec(HORIZON),
        answer: Arc::new(|_| Ok(vec![STILL; 3])),
    };
    let out = offline(&mut short, &opts());
    for t in &out.tasks {
        assert_eq!(t.failed, t.samples);
        assert_eq!(t.mse, FAILED_PREDICTION_MSE);
        assert!(t.failure.as_deref().unwrap().contains("got 3 actions"));
    }
}

/// Contract v1.1 offline: a policy asking for 3 frames and 4 actions per chunk is sampled every
/// 4 expert steps of a task and sees the 2 steps before each sample, rendered, with the hand
/// pose and the expert's previous action.
#[test]
fn offline_samples_show_the_history_and_count_the_policy_asked_for() {
    type Seen = Vec<(u64, usize, Vec<(u64, usize, bool)>)>;
    let seen: Arc<std::sync::Mutex<Seen>> = Arc::default();
    let log = seen.clone();
    let mut p = Scripted {
        spec: kitchen_r_episode::policy::PolicySpec {
            observation_history: 3,
            actions_executed_per_chunk: Some(4),
            ..spec(HORIZON)
        },
        answer: Arc::new(move |i| {
            let frames = (i.history.iter())
                .map(|f| (f.step, f.observation.images.len(), f.previous_action.is_some()))
                .collect();
            log.lock()
                .unwrap()
                .push((i.step, i.observation.images.len(), frames));
            Ok(vec![STILL; HORIZON])
        }),
    };
    let opts = OfflineOptions {
        max_tasks: Some(1),
        ..opts()
    };
    let out = offline(&mut p, &opts);
    let seen = seen.lock().unwrap().clone();
    assert_eq!(out.tasks[0].samples as usize, seen.len());
    for (n, (step, images, earlier)) in seen.iter().enumerate() {
        assert_eq!(*step, 4 * n as u64, "a decision point every 4 steps of the task");
        assert_eq!(*images, 2);
        let want: Vec<u64> = (step.saturating_sub(2)..*step).collect();
        let steps: Vec<u64> = earlier.iter().map(|f| f.0).collect();
        assert_eq!(
            steps, want,
            "the steps before, oldest first (fewer at the task's start)"
        );
        for &(s, imgs, previous) in earlier {
            assert_eq!(imgs, 2, "history frames are rendered");
            assert_eq!(previous, s > 0, "the expert's action that led to step {s}");
        }
    }
}
