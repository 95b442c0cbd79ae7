//! The oracle must be able to do what the benchmark asks (DESIGN, Feasibility: every generated
//! instruction is executable by the oracle): it completes every task of every instruction of the
//! committed dev split through the same evaluation code path as `kitchen-r eval --policy
//! builtin:oracle` and the runner participants are scored by. The whole check over all 563
//! committed instructions is that command over both splits (see docs/twin/scenes.md, Feasibility).

use kitchen_r_core::dataset::Split;
use kitchen_r_episode::eval::{EvalOptions, EvalReport, episode_configs, evaluate, instructions};
use kitchen_r_episode::oracle::OraclePolicy;
use kitchen_r_episode::runner::{RunOptions, StepHook, run_episode};
use kitchen_r_sim::{Action, Assets, SensorsConfig, Sim, SimConfig, StepInfo};

#[test]
fn oracle_completes_every_task_of_the_dev_split() {
    let opts = EvalOptions {
        jobs: std::thread::available_parallelism().map_or(1, |n| n.get()),
        ..EvalOptions::default()
    };
    let report: EvalReport = evaluate(&opts, &mut |_, _| {}).unwrap();
    let failures: Vec<String> = report
        .episodes
        .iter()
        .flat_map(|e| {
            e.tasks.iter().filter(|t| !t.success).map(move |t| {
                format!(
                    "{} task {} {:?}: {}",
                    e.episode_id,
                    t.index,
                    t.step,
                    t.failure.clone().unwrap_or_default()
                )
            })
        })
        .collect();
    eprintln!(
        "oracle: {} of {} tasks of {} dev instructions in {:.1} s wall ({} jobs)",
        report.overall.succeeded,
        report.overall.tasks,
        report.episodes.len(),
        report.total_wall_s,
        report.jobs
    );
    let all = instructions(Split::Dev, None).unwrap();
    assert_eq!(report.episodes.len(), all.len(), "every dev instruction runs");
    assert!(
        failures.is_empty(),
        "the oracle failed {} of {} dev tasks:\n{}",
        failures.len(),
        report.overall.tasks,
        failures.join("\n")
    );
}

/// Records the largest planar distance the base moved in one control step.
struct LargestJump {
    last: Option<[f64; 3]>,
    largest: (f64, f64),
}

impl StepHook for LargestJump {
    fn on_step(&mut self, _: &Sim, _: &Action, info: &StepInfo) -> Result<(), String> {
        let p = info.base_pose;
        if let Some(l) = self.last {
            let d = (p[0] - l[0]).hypot(p[1] - l[1]);
            if d > self.largest.0 {
                self.largest = (d, info.time);
            }
        }
        self.last = Some(p);
        Ok(())
    }
}

/// Regression: in dev-0006 with run seed 0 the base used to drift into the floor over ~85 s of
/// driving and was then flung metres across the kitchen (a floor contact along the locked height
/// axis). The base never moves faster than its speed limit (0.5 m/s), so one 0.1 s step moves it
/// at most 5 cm.
#[test]
fn the_base_is_never_flung_during_a_long_oracle_episode() {
    let assets = Assets::load_default().unwrap();
    let dev: Vec<_> = instructions(Split::Dev, None)
        .unwrap()
        .into_iter()
        .filter(|i| i.id == "dev-0006")
        .collect();
    let cfg = &episode_configs(&assets, &dev, 0, None).unwrap()[0];
    let (mut sim, _) = Sim::new(
        assets.clone(),
        SimConfig::load_default().unwrap(),
        SensorsConfig::load_default().unwrap(),
        cfg,
    )
    .unwrap();
    let run = RunOptions {
        privileged: true,
        ..RunOptions::default()
    };
    let mut hook = LargestJump {
        last: None,
        largest: (0.0, 0.0),
    };
    let outcome = run_episode(&mut sim, &mut OraclePolicy::new(&assets), &run, None, &mut hook).unwrap();
    let (jump, at) = hook.largest;
    assert!(
        jump <= 0.051,
        "the base moved {jump:.3} m in one step at t = {at:.1} s"
    );
    assert!(outcome.tasks.iter().all(|t| t.success), "{:?}", outcome.tasks);
}
