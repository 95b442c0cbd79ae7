//! An episode driven one action at a time (`kitchen_r_episode::driven`, the Python environment's
//! `step`) is the runner's episode: driven by the expert's chunks it is bit-identical to
//! `run_episode` with the oracle, bad actions are refused without stepping, and a driver that
//! stops early gets its simulator back.

use kitchen_r_core::dataset::Split;
use kitchen_r_episode::driven::{DriveError, DriveOptions, DrivenEpisode, Next};
use kitchen_r_episode::eval::{episode_configs, instructions};
use kitchen_r_episode::oracle::OraclePolicy;
use kitchen_r_episode::runner::{EpisodeOutcome, RunOptions, TaskRecord, run_episode};
use kitchen_r_sim::{Assets, EpisodeConfig, SensorsConfig, Sim, SimConfig};

const EXECUTE: usize = 8;

fn setup(n: usize) -> (Assets, Vec<EpisodeConfig>) {
    let assets = Assets::load_default().unwrap();
    let ins = instructions(Split::Dev, None).unwrap();
    let configs = episode_configs(&assets, &ins, 0, Some(n)).unwrap();
    (assets, configs)
}

fn new_sim(assets: &Assets, cfg: &EpisodeConfig) -> Sim {
    Sim::new(
        assets.clone(),
        SimConfig::default(),
        SensorsConfig::default(),
        cfg,
    )
    .unwrap()
    .0
}

/// The expert drives: asked at each task's start and after every `EXECUTE` actions, its chunk's
/// first `EXECUTE` actions executed, as the runner does with `execute = EXECUTE`.
fn drive_with_expert(assets: &Assets, cfg: &EpisodeConfig) -> (Vec<TaskRecord>, EpisodeOutcome) {
    let opts = DriveOptions {
        teleport_on_failure: false,
        images: false,
        ..DriveOptions::default()
    };
    let (mut ep, mut progress) =
        DrivenEpisode::start(new_sim(assets, cfg), cfg.clone(), assets, &opts).unwrap();
    let mut live = Vec::new();
    let mut queue: Vec<[f64; 10]> = Vec::new();
    let mut task = usize::MAX;
    loop {
        live.extend(progress.tasks_ended.iter().cloned());
        let d = match progress.next {
            Next::Decision(d) => d,
            Next::Ended(end) => {
                assert!(ep.finish().is_some(), "the simulator comes back");
                return (live, end.outcome);
            }
        };
        if d.task_index != task {
            task = d.task_index;
            queue.clear();
        }
        if queue.is_empty() {
            let chunk = ep.expert_chunk().unwrap();
            queue = chunk[..EXECUTE].iter().rev().copied().collect();
        }
        progress = ep.act(queue.pop().unwrap()).unwrap();
    }
}

#[test]
fn the_expert_driving_one_action_at_a_time_is_the_runners_oracle_episode_bit_for_bit() {
    let (assets, configs) = setup(3);
    for cfg in &configs {
        let mut sim = new_sim(&assets, cfg);
        let run = RunOptions {
            execute: EXECUTE,
            privileged: true,
            ..RunOptions::default()
        };
        let mut oracle = OraclePolicy::new(&assets).without_images();
        let want = run_episode(&mut sim, &mut oracle, &run, None, &mut ()).unwrap();
        let (live, got) = drive_with_expert(&assets, cfg);
        assert_eq!(got.tasks.len(), want.tasks.len(), "{}", cfg.id);
        for (g, w) in got.tasks.iter().zip(&want.tasks) {
            assert_eq!(
                (g.index, g.success, &g.failure),
                (w.index, w.success, &w.failure),
                "{}",
                cfg.id
            );
            assert_eq!(
                g.sim_time.to_bits(),
                w.sim_time.to_bits(),
                "{} task {}",
                cfg.id,
                g.index
            );
        }
        assert_eq!(got.sim_time.to_bits(), want.sim_time.to_bits(), "{}", cfg.id);
        assert!(
            want.tasks.iter().all(|t| t.success),
            "the oracle succeeds on {}",
            cfg.id
        );
        // Every task's end was told as it happened.
        assert_eq!(live, got.tasks, "{}", cfg.id);
    }
}

#[test]
fn bad_actions_are_refused_without_stepping_and_a_stopped_driver_gets_its_simulator_back() {
    let (assets, configs) = setup(1);
    let cfg = &configs[0];
    let opts = DriveOptions {
        teleport_on_failure: false,
        images: false,
        expert: false,
        ..DriveOptions::default()
    };
    let (mut ep, first) = DrivenEpisode::start(new_sim(&assets, cfg), cfg.clone(), &assets, &opts).unwrap();
    let Next::Decision(d) = first.next else {
        panic!("a first decision")
    };
    assert_eq!((d.step, d.task_index), (0, 0));
    assert_eq!(d.sub_task, cfg.plan[0]);
    let still = [
        0.0,
        0.0,
        d.ee_pose[0],
        d.ee_pose[1],
        d.ee_pose[2],
        d.ee_pose[3],
        d.ee_pose[4],
        d.ee_pose[5],
        d.ee_pose[6],
        1.0,
    ];
    let mut nan = still;
    nan[0] = f64::NAN;
    let mut not_unit = still;
    not_unit[5] = 3.0;
    for bad in [nan, not_unit] {
        assert!(matches!(ep.act(bad), Err(DriveError::BadAction(_))), "{bad:?}");
    }
    assert!(matches!(ep.expert_chunk(), Err(DriveError::NoExpert)));
    let p = ep.act(still).unwrap();
    let Next::Decision(d) = p.next else {
        panic!("a second decision")
    };
    assert_eq!(d.step, 1, "only the good action was executed");
    assert_eq!(d.previous_action, Some(still));
    let sim = ep
        .finish()
        .expect("the simulator comes back from an abandoned episode");
    assert_eq!(sim.episode().id, cfg.id);
}
