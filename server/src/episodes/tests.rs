use super::*;
use kitchen_r_core::metrics::FAILED_PREDICTION_MSE;

fn spec(mode: Mode, id: &str, plan: &[&str]) -> JobSpec {
    JobSpec {
        mode,
        scene_id: "kitchen_a".into(),
        instruction_id: id.into(),
        plan: plan.iter().map(|s| s.to_string()).collect(),
        seed: 7,
        task_time_limit_s: 120.0,
        actions_executed_per_chunk: 8,
        teleport_on_failure: true,
        max_plan_steps: 0,
        privileged: false,
        privileged_observations: None,
        endpoint: EndpointSpec {
            url: "http://127.0.0.1:1".into(),
            bearer_token: String::new(),
            bearer_token_sealed: None,
            call_deadline_ms: 1,
            startup_deadline_ms: 1,
            episode_budget_ms: 1,
            max_successive_timeouts: 1,
            min_actions_executed_per_chunk: 0,
            quat_norm_tolerance: None,
            gripper_margin: None,
            key_map: None,
        },
        place_targets: Vec::new(),
        grasp: kitchen_r_core::GraspMode::Abstract,
    }
}

fn task(index: u32, success: bool, mse: f64, mse_samples: u32) -> TaskOutcome {
    TaskOutcome {
        index,
        step: String::new(),
        success,
        completion_time_s: if success { 3.0 } else { 0.0 },
        failure_reason: if success { String::new() } else { "timeout".into() },
        mse,
        mse_samples,
    }
}

const A: [&str; 4] = ["a1", "a2", "a3", "a4"];
const B: [&str; 2] = ["b1", "b2"];

/// Two instructions, online and offline; B's episodes stopped after their first task, and A's
/// offline task 2 came back failed without a sample: each of those costs one failed prediction.
fn run() -> Vec<Episode> {
    let ep = |spec, tasks| Episode {
        spec,
        tasks,
        failure: None,
    };
    vec![
        ep(
            spec(Mode::Online, "a", &A),
            vec![
                task(0, true, 0.0, 0),
                task(1, true, 0.0, 0),
                task(2, false, 0.0, 0),
                task(3, true, 0.0, 0),
            ],
        ),
        ep(spec(Mode::Online, "b", &B), vec![task(0, false, 0.0, 0)]),
        ep(
            spec(Mode::Offline, "a", &A),
            vec![
                task(0, false, 0.1, 2),
                task(1, false, 0.3, 2),
                task(2, false, 0.2, 0),
                task(3, false, 0.5, 4),
            ],
        ),
        ep(spec(Mode::Offline, "b", &B), vec![task(0, false, 1.0, 2)]),
    ]
}

fn close(a: Option<f64>, b: f64) -> bool {
    a.is_some_and(|a| (a - b).abs() < 1e-12)
}

#[test]
fn control_run_sr_and_mse_by_hand() {
    let s = aggregate(&run(), None);
    // SR: a = 3/4, b = 0/2 (the unreported task counts as failed) → 0.375.
    assert!(close(s.sr, 0.375), "{s:?}");
    // MSE: (0.1·2 + 0.3·2 + 4·1 + 0.5·4 + 1.0·2 + 4·1) / (2 + 2 + 1 + 4 + 2 + 1) = 12.8 / 12.
    assert!(close(s.mse, 12.8 / 12.0), "{s:?}");
    assert_eq!((s.em, s.m, s.p), (None, None, None));
}

#[test]
fn integrated_run_m_and_p_by_hand() {
    let plans: HashMap<String, Vec<String>> = [(
        "a".to_string(),
        vec!["a1".into(), "a2".into(), "x".into(), "a4".into()],
    )]
    .into();
    let s = aggregate(&run(), Some(&plans));
    // EM: a = 3/4, b missing = 0 → 0.375.
    assert!(close(s.em, 0.375), "{s:?}");
    // M: a = (2 + 2 + 0 + 2) / 4 = 1.5, b = 0 → 0.75.
    assert!(close(s.m, 0.75), "{s:?}");
    // P: 1/0.375 + mean(a = mean(0.1, 0.3, 4, 0.5) = 1.225, b = mean(1, 4) = 2.5) = 8/3 + 1.8625.
    assert!(close(s.p, 8.0 / 3.0 + 1.8625), "{s:?}");
}

#[test]
fn zero_em_gives_infinite_p_not_a_crash() {
    let plans: HashMap<String, Vec<String>> = HashMap::new();
    let s = aggregate(&run(), Some(&plans));
    assert_eq!(s.em, Some(0.0));
    assert_eq!(s.p, Some(f64::INFINITY));
    // M is then SR alone: (3/4 + 0) / 2.
    assert!(close(s.m, 0.375));
}

#[test]
fn max_plan_steps_caps_the_tasks_scored() {
    let mut eps = run();
    for e in &mut eps {
        e.spec.max_plan_steps = 2;
    }
    let s = aggregate(&eps, None);
    // a: tasks 0 and 1 succeeded → 1; b: 0 → SR 0.5. MSE only over tasks 0..2, b's unreported
    // task 1 a failed prediction: (0.2 + 0.6 + 2.0 + 4) / 7.
    assert!(close(s.sr, 0.5), "{s:?}");
    assert!(close(s.mse, 6.8 / 7.0), "{s:?}");
}

#[test]
fn platform_failed_episode_scores_zero_and_no_mse() {
    let eps = vec![Episode {
        spec: spec(Mode::Online, "a", &A),
        tasks: vec![],
        failure: Some("gave up".into()),
    }];
    let s = aggregate(&eps, None);
    assert_eq!(s.sr, Some(0.0));
    assert_eq!(s.mse, None);
}

#[test]
fn bad_mse_from_a_worker_is_dropped() {
    let t = pb::TaskResult {
        mse: f64::NAN,
        mse_samples: 3,
        ..Default::default()
    };
    let o = TaskOutcome::from(&t);
    assert_eq!((o.mse, o.mse_samples), (0.0, 0));
}

#[test]
fn spec_round_trips_through_json_and_proto() {
    let mut s = spec(Mode::Offline, "dev-0007", &A);
    s.privileged = true;
    let back: JobSpec = serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
    assert_eq!(back, s);
    let p = s.episode_proto("ep-x");
    assert_eq!(p.mode, pb::EvalMode::Offline as i32);
    assert!(p.privileged);
    assert_eq!(Mode::Offline.episode_key("dev-0007"), "dev-0007/offline");
}

#[test]
fn refusing_the_offline_episodes_never_beats_answering() {
    let plans: HashMap<String, Vec<String>> =
        [("a".to_string(), A.iter().map(|s| s.to_string()).collect())].into();
    let online = |id| Episode {
        spec: spec(Mode::Online, id, &A),
        tasks: (0..4).map(|j| task(j, true, 0.0, 0)).collect(),
        failure: None,
    };
    // The honest policy answers every decision point, badly (MSE 3, the worst inside the ranges
    // is 4); the dodging one refuses its offline episode at the handshake (every task reported
    // failed, no sample) or not at all (nothing reported).
    let honest = vec![
        online("a"),
        Episode {
            spec: spec(Mode::Offline, "a", &A),
            tasks: (0..4).map(|j| task(j, false, 3.0, 20)).collect(),
            failure: None,
        },
    ];
    let refused = vec![
        online("a"),
        Episode {
            spec: spec(Mode::Offline, "a", &A),
            tasks: (0..4)
                .map(|j| TaskOutcome {
                    failure_reason: "policy unreachable: UNAVAILABLE".into(),
                    ..task(j, false, 0.0, 0)
                })
                .collect(),
            failure: None,
        },
    ];
    let silent = vec![
        online("a"),
        Episode {
            spec: spec(Mode::Offline, "a", &A),
            tasks: Vec::new(),
            failure: None,
        },
    ];
    let h = aggregate(&honest, Some(&plans));
    for dodge in [refused, silent] {
        let d = aggregate(&dodge, Some(&plans));
        assert_eq!(d.m, h.m);
        assert!(d.mse.unwrap() > h.mse.unwrap(), "{d:?} vs {h:?}");
        assert!(d.p.unwrap() > h.p.unwrap(), "{d:?} vs {h:?}");
        assert_eq!(d.mse, Some(FAILED_PREDICTION_MSE));
    }
}
