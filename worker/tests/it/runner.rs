//! The episode runner judges policies, never trusts them: a policy that stands still fails on the
//! time limit, a bad chunk fails its task with the reason, successive timeouts abort the episode,
//! and the run always completes with one outcome per plan step.

use crate::remote_support;

use kitchen_r_episode::policy::{HORIZON, Policy, PolicyError, PolicyInput, PolicySpec};
use kitchen_r_episode::runner::{RunOptions, run_episode};
use remote_support::sim;

struct Scripted {
    spec: PolicySpec,
    answer: fn(u64) -> Result<Vec<[f64; 10]>, PolicyError>,
    resets: usize,
}

impl Policy for Scripted {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }
    fn reset(&mut self, _: &str, _: usize, _: &str) -> Result<(), PolicyError> {
        self.resets += 1;
        Ok(())
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; 10]>, PolicyError> {
        assert!(
            input.privileged.is_none(),
            "participants never get privileged state"
        );
        (self.answer)(input.step)
    }
}

const STILL: [f64; 10] = [0.0, 0.0, 0.35, 0.0, 0.95, 0.0, 1.0, 0.0, 0.0, 1.0];

fn policy(answer: fn(u64) -> Result<Vec<[f64; 10]>, PolicyError>) -> Scripted {
    Scripted {
        spec: PolicySpec {
            name: "scripted".into(),
            ..PolicySpec::default()
        },
        answer,
        resets: 0,
    }
}

fn opts() -> RunOptions {
    RunOptions {
        task_time_limit: 3.0,
        ..RunOptions::default()
    }
}

#[test]
fn a_policy_that_stands_still_fails_every_task_on_the_time_limit() {
    let mut sim = sim();
    let plan_len = sim.episode().plan.len();
    let mut p = policy(|_| Ok(vec![STILL; HORIZON]));
    let out = run_episode(&mut sim, &mut p, &opts(), None, &mut ()).unwrap();
    assert_eq!(out.tasks.len(), plan_len);
    assert_eq!(p.resets, plan_len);
    for t in &out.tasks {
        assert!(!t.success);
        // The reason says what ran out and how far the task was from success.
        let f = t.failure.as_deref().unwrap_or_default();
        assert!(f.starts_with("time limit of 3 s reached: "), "{f}");
        if t.step.starts_with("move to") {
            assert!(f.contains("the base centre ended"), "{f}");
        } else if t.step.starts_with("pick") {
            assert!(f.contains("was not grasped"), "{f}");
        }
        assert!((t.sim_time - 3.0).abs() < 0.051, "{}", t.sim_time);
    }
    assert_eq!(out.success_rate(), 0.0);
}

#[test]
fn a_nan_chunk_fails_its_task_with_the_reason_and_the_run_goes_on() {
    let mut sim = sim();
    let mut p = policy(|_| {
        let mut c = vec![STILL; HORIZON];
        c[2][0] = f64::NAN;
        Ok(c)
    });
    let out = run_episode(&mut sim, &mut p, &opts(), None, &mut ()).unwrap();
    assert_eq!(out.tasks.len(), sim.episode().plan.len());
    for t in &out.tasks {
        assert_eq!(
            t.failure.as_deref(),
            Some("invalid action chunk: action 2 value 0 is not finite")
        );
        assert_eq!(t.policy_calls, 1);
    }
}

#[test]
fn successive_timeouts_abort_the_rest_of_the_episode() {
    let mut sim = sim();
    let mut p = policy(|_| Err(PolicyError::Timeout(2.0)));
    let out = run_episode(&mut sim, &mut p, &opts(), None, &mut ()).unwrap();
    let reasons: Vec<_> = out.tasks.iter().map(|t| t.failure.clone().unwrap()).collect();
    assert!(reasons[0].contains("did not answer within 2.0 s"));
    assert!(
        reasons[2].starts_with("episode aborted: 3 successive timeouts"),
        "{reasons:?}"
    );
    assert!(reasons[3..].iter().all(|r| r == &reasons[2]));
    assert_eq!(p.resets, 3, "no task is started after the abort");
}

#[test]
fn max_tasks_limits_the_executed_plan_steps() {
    let mut sim = sim();
    let mut p = policy(|_| Ok(vec![STILL; HORIZON]));
    let o = RunOptions {
        max_tasks: Some(2),
        ..opts()
    };
    let out = run_episode(&mut sim, &mut p, &o, None, &mut ()).unwrap();
    assert_eq!(out.tasks.len(), 2);
}

/// Records what each decision showed and counts the frames the runner asked images for.
struct Watcher {
    spec: PolicySpec,
    /// Per Act: the step, the steps of the earlier frames, whether each frame had images.
    seen: Vec<(u64, Vec<u64>, bool)>,
    chunk: Vec<[f64; 10]>,
}

impl Policy for Watcher {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }
    fn reset(&mut self, _: &str, _: usize, _: &str) -> Result<(), PolicyError> {
        Ok(())
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; 10]>, PolicyError> {
        let imaged = !input.observation.images.is_empty()
            && input.history.iter().all(|f| !f.observation.images.is_empty());
        let steps = input.history.iter().map(|f| f.step).collect();
        self.seen.push((input.step, steps, imaged));
        Ok(self.chunk.clone())
    }
    /// Asked once per frame the runner captures, just before rendering it (`&self`: counted
    /// in a thread-local).
    fn wants_images(&self) -> bool {
        RENDERS.with(|r| r.set(r.get() + 1));
        true
    }
}

thread_local! {
    static RENDERS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

fn watcher(history: usize, execute: Option<usize>) -> Watcher {
    Watcher {
        spec: PolicySpec {
            name: "watcher".into(),
            observation_history: history,
            actions_executed_per_chunk: execute,
            ..PolicySpec::default()
        },
        seen: Vec::new(),
        chunk: vec![STILL; HORIZON],
    }
}

/// One 3 s task with `p`; the frames rendered.
fn watch(p: &mut Watcher) -> usize {
    RENDERS.with(|r| r.set(0));
    let o = RunOptions {
        max_tasks: Some(1),
        ..opts()
    };
    run_episode(&mut sim(), p, &o, None, &mut ()).unwrap();
    RENDERS.with(std::cell::Cell::get)
}

#[test]
fn only_the_frames_a_decision_shows_are_rendered() {
    // v1: one frame per query, every 8 steps (30 steps: queries at 0, 8, 16, 24).
    let mut v1 = watcher(1, None);
    assert_eq!(watch(&mut v1), 4);
    let steps: Vec<u64> = v1.seen.iter().map(|s| s.0).collect();
    assert_eq!(steps, [0, 8, 16, 24]);
    assert!(v1.seen.iter().all(|s| s.1.is_empty() && s.2));

    // History 2, 4 per chunk: the task's first frame, then 2 per chunk for the 7 chunks that
    // end in a query (the 8th is cut by the time limit at step 30).
    let mut h2 = watcher(2, Some(4));
    assert_eq!(watch(&mut h2), 1 + 7 * 2);
    let steps: Vec<u64> = h2.seen.iter().map(|s| s.0).collect();
    assert_eq!(steps, [0, 4, 8, 12, 16, 20, 24, 28]);
    assert_eq!(
        h2.seen[0].1,
        Vec::<u64>::new(),
        "nothing before the task's first step"
    );
    for (step, earlier, imaged) in &h2.seen[1..] {
        assert_eq!(earlier, &[step - 1]);
        assert!(imaged);
    }
}

#[test]
fn a_history_longer_than_a_part_chunk_spans_earlier_chunks() {
    let mut p = watcher(6, Some(4));
    // Longer than a part-chunk: every step of the task is a frame some decision shows.
    assert_eq!(watch(&mut p), 1 + 29);
    for (step, earlier, imaged) in &p.seen {
        let first = step.saturating_sub(5);
        let want: Vec<u64> = (first..*step).collect();
        assert_eq!(earlier, &want, "step {step}");
        assert!(imaged);
    }
}

#[test]
fn slips_within_tolerance_are_corrected_and_counted_per_task() {
    let mut p = watcher(1, None);
    p.chunk[0][9] = 1.0001;
    p.chunk[1][5..9].copy_from_slice(&[0.0, 1.02, 0.0, 0.0]);
    let o = RunOptions {
        max_tasks: Some(2),
        ..opts()
    };
    let out = run_episode(&mut sim(), &mut p, &o, None, &mut ()).unwrap();
    for t in &out.tasks {
        let f = t.failure.as_deref().unwrap_or_default();
        assert!(
            f.starts_with("time limit of 3 s reached"),
            "not a chunk failure: {f}"
        );
        // 4 chunks per task, each with one gripper clamped and one quaternion normalised.
        assert_eq!((t.corrections.grippers, t.corrections.quaternions), (4, 4));
        assert!(t.corrections.warning().unwrap().starts_with("8 corrections"));
    }
    p.chunk[0][9] = 1.2;
    let out = run_episode(&mut sim(), &mut p, &o, None, &mut ()).unwrap();
    let f = out.tasks[0].failure.as_deref().unwrap();
    assert!(
        f.contains("action 0: gripper 1.2 outside [0, 1] (margin 0.05)"),
        "{f}"
    );
}
