use std::time::Duration;

use kitchen_r_core::GraspMode;
use kitchen_r_core::dataset::Split;
use kitchen_r_sim::{Assets, EpisodeConfig};

use super::*;
use crate::eval::{episode_configs, instructions};
use crate::oracle::OraclePolicy;
use crate::runner::run_episode;
use crate::teleport::expert_starts;

fn first_dev_episode(assets: &Assets) -> EpisodeConfig {
    let dev = instructions(Split::Dev, None).unwrap();
    episode_configs(assets, &dev[..1], 0, None).unwrap().remove(0)
}

/// Runs `policy` over `cfg` as `eval` does (a fresh simulator, optional teleport starts) with a
/// [`TracingPolicy`] around it, and returns the trace read back from its JSON.
fn traced<P: Policy>(
    assets: &Assets,
    cfg: &EpisodeConfig,
    policy: P,
    run: &RunOptions,
    teleport: bool,
) -> Trace {
    traced_in(None, assets, cfg, policy, run, teleport)
}

/// [`traced`] with the simulator in grasp mode `grasp` (`None`: sim.toml's).
fn traced_in<P: Policy>(
    grasp: Option<GraspMode>,
    assets: &Assets,
    cfg: &EpisodeConfig,
    policy: P,
    run: &RunOptions,
    teleport: bool,
) -> Trace {
    let (mut sim_cfg, sensors) = (
        kitchen_r_sim::SimConfig::load_default().unwrap(),
        kitchen_r_sim::SensorsConfig::load_default().unwrap(),
    );
    if let Some(g) = grasp {
        sim_cfg.grasp.mode = g;
    }
    let mut slot = None;
    let sim = crate::sim_slot::load(&mut slot, assets, &sim_cfg, &sensors, cfg).unwrap();
    let starts = teleport.then(|| expert_starts(sim, cfg, assets).unwrap());
    let mut tracing = TracingPolicy::new(policy);
    let out = run_episode(sim, &mut tracing, run, starts.as_deref(), &mut ()).unwrap();
    let trace = tracing.into_trace(cfg.clone(), run, sim_cfg.grasp.mode, teleport, &out);
    Trace::from_json(&trace.to_json()).unwrap()
}

fn oracle_run(max_tasks: usize) -> RunOptions {
    RunOptions {
        privileged: true,
        max_tasks: Some(max_tasks),
        ..RunOptions::default()
    }
}

#[test]
fn chunk_values_read_back_bit_for_bit_including_what_json_has_no_number_for() {
    let odd = [
        -0.0,
        f64::MIN_POSITIVE / 3.0,
        1e-300,
        0.1 + 0.2,
        -123456.789e10,
        f64::MAX,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
        1.0,
    ];
    let call = Call::Act {
        task: 2,
        step: 7,
        chunk: Some(vec![odd, [0.5; ACTION_DIM]]),
        error: None,
    };
    let back: Call = serde_json::from_slice(&serde_json::to_vec(&call).unwrap()).unwrap();
    let Call::Act { chunk: Some(c), .. } = back else {
        panic!("{back:?}")
    };
    for (a, b) in c[0].iter().zip(odd) {
        assert!(
            a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
            "{a} {b}"
        );
    }
    let err = Call::Act {
        task: 0,
        step: 0,
        chunk: None,
        error: Some(PolicyError::Timeout(2.5)),
    };
    let json = serde_json::to_string(&err).unwrap();
    assert_eq!(serde_json::from_str::<Call>(&json).unwrap(), err, "{json}");
}

#[test]
fn an_oracle_episode_replays_bit_identically_and_a_tampered_action_is_refused() {
    let assets = Assets::load_default().unwrap();
    let cfg = first_dev_episode(&assets);
    let run = oracle_run(2);
    let trace = traced(&assets, &cfg, OraclePolicy::new(&assets), &run, false);
    assert!(
        trace.outcome.tasks.iter().all(|t| t.success),
        "{:?}",
        trace.outcome
    );
    let replayed = replay(&trace, &mut ()).unwrap();
    assert_eq!(TraceOutcome::of(&replayed), trace.outcome);

    // One executed action a little off: the robot ends elsewhere, and the replay says so.
    let mut tampered = trace.clone();
    let Some(Call::Act { chunk: Some(c), .. }) =
        tampered.calls.iter_mut().find(|c| matches!(c, Call::Act { .. }))
    else {
        panic!("no act call")
    };
    c[0][0] += 0.05;
    match replay(&tampered, &mut ()) {
        Err(ReplayError::Disagrees { what }) => assert!(what.contains("the replay asked"), "{what}"),
        other => panic!("a tampered trace replayed: {other:?}"),
    }
}

#[test]
fn a_trace_records_its_grasp_mode_and_replays_in_it_whatever_the_replaying_config_says() {
    let assets = Assets::load_default().unwrap();
    let cfg = first_dev_episode(&assets);
    let run = oracle_run(1);
    let trace = traced_in(
        Some(GraspMode::Physical),
        &assets,
        &cfg,
        OraclePolicy::new(&assets),
        &run,
        false,
    );
    assert_eq!(trace.run.grasp, GraspMode::Physical);
    let json = String::from_utf8(trace.to_json()).unwrap();
    assert!(json.contains(r#""grasp":"physical""#), "{json:.300}");
    // The replaying side's own config says abstract; the trace's mode wins.
    let mut abstract_cfg = kitchen_r_sim::SimConfig::load_default().unwrap();
    abstract_cfg.grasp.mode = GraspMode::Abstract;
    assert_eq!(
        replay_config(&trace, &abstract_cfg).grasp.mode,
        GraspMode::Physical
    );
    let sensors = kitchen_r_sim::SensorsConfig::load_default().unwrap();
    let replayed = replay_with(&trace, &assets, &abstract_cfg, &sensors, &mut ()).unwrap();
    assert_eq!(TraceOutcome::of(&replayed), trace.outcome);

    // An abstract trace does not name its mode (older builds replay it); one recorded before
    // the field existed reads as abstract.
    let mut old = trace.clone();
    old.run.grasp = GraspMode::Abstract;
    let json = old.to_json();
    assert!(!String::from_utf8_lossy(&json).contains("grasp"));
    assert_eq!(Trace::from_json(&json).unwrap().run.grasp, GraspMode::Abstract);
}

/// The oracle, except that some answers are what participants' policies get wrong: a failed
/// reset, a chunk with a NaN, a timeout, a quaternion a little off (corrected, not failed).
struct Flaky {
    oracle: OraclePolicy,
    acts: u32,
}

impl Policy for Flaky {
    fn spec(&self) -> &PolicySpec {
        self.oracle.spec()
    }
    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        if task_index == 2 {
            return Err(PolicyError::Call("reset refused".into()));
        }
        self.oracle.reset(episode_id, task_index, sub_task)
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        self.acts += 1;
        let mut c = self.oracle.act(input)?;
        match self.acts {
            3 => c[0][3] *= 1.01,
            6 => c[15][9] = f64::NAN,
            _ if input.task_index == 1 && self.acts > 12 => {
                return Err(PolicyError::Timeout(1.5));
            }
            _ => {}
        }
        Ok(c)
    }
    fn wants_images(&self) -> bool {
        false
    }
}

#[test]
fn a_policy_that_errs_and_sends_bad_chunks_replays_bit_identically_with_teleports() {
    let assets = Assets::load_default().unwrap();
    let cfg = first_dev_episode(&assets);
    let flaky = Flaky {
        oracle: OraclePolicy::new(&assets).without_images(),
        acts: 0,
    };
    let trace = traced(&assets, &cfg, flaky, &oracle_run(4), true);
    let failures: Vec<&str> = trace
        .outcome
        .tasks
        .iter()
        .filter_map(|t| t.failure.as_deref())
        .collect();
    assert!(
        failures.iter().any(|f| f.contains("invalid action chunk")),
        "{failures:?}"
    );
    assert!(
        failures.iter().any(|f| f.contains("reset refused")),
        "{failures:?}"
    );
    assert!(
        failures.iter().any(|f| f.contains("did not answer")),
        "{failures:?}"
    );
    let replayed = replay(&trace, &mut ()).unwrap();
    assert_eq!(TraceOutcome::of(&replayed), trace.outcome);
}

/// The oracle, slowed down once, so the episode's wall budget runs out.
struct Slow(OraclePolicy, u32);

impl Policy for Slow {
    fn spec(&self) -> &PolicySpec {
        self.0.spec()
    }
    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        self.0.reset(episode_id, task_index, sub_task)
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        self.1 += 1;
        if self.1 == 4 {
            std::thread::sleep(Duration::from_millis(400));
        }
        self.0.act(input)
    }
    fn wants_images(&self) -> bool {
        false
    }
}

#[test]
fn a_wall_budget_abort_replays_at_the_recorded_decision_without_real_time() {
    let assets = Assets::load_default().unwrap();
    let cfg = first_dev_episode(&assets);
    let run = RunOptions {
        wall_budget: Some(Duration::from_millis(300)),
        ..oracle_run(3)
    };
    let slow = Slow(OraclePolicy::new(&assets).without_images(), 0);
    let trace = traced(&assets, &cfg, slow, &run, false);
    let at = trace.budget_abort_at.expect("the budget ran out");
    assert!(at.calls >= 4 || at.task > 0, "{at:?}");
    assert!(
        trace
            .outcome
            .tasks
            .last()
            .unwrap()
            .failure
            .as_deref()
            .unwrap()
            .contains("budget")
    );
    let replayed = replay(&trace, &mut ()).unwrap();
    assert_eq!(TraceOutcome::of(&replayed), trace.outcome);

    // Without the recorded abort the replay runs on and is refused.
    let mut no_abort = trace.clone();
    no_abort.budget_abort_at = None;
    assert!(matches!(
        replay(&no_abort, &mut ()),
        Err(ReplayError::Disagrees { .. })
    ));
}

#[test]
fn a_file_that_is_not_a_trace_of_this_version_is_refused_before_any_simulation() {
    let err = Trace::from_json(br#"{"format":"kitchen-r-trace","version":99}"#).unwrap_err();
    assert!(matches!(err, ReplayError::Format(_)), "{err}");
    assert!(Trace::from_json(b"[]").is_err());
}
