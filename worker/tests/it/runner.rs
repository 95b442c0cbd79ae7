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
            horizon: HORIZON,
            action_dim: 10,
            cameras: vec![],
            max_concurrency: 1,
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
        assert_eq!(t.failure.as_deref(), Some("time limit of 3 s reached"));
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
