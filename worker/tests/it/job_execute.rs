//! `execute_job`: a leased job turned into an episode result, with the oracle over gRPC as the
//! policy (a privileged reference run), online and offline; policy faults as task failures with
//! reasons, platform faults as `platform_error`.

use crate::remote_support;

use std::sync::{Arc, OnceLock};

use kitchen_r_contract::server::{PolicyFactory, ServeOptions};
use kitchen_r_contract::{AllowedNetworks, RemoteConfig};
use kitchen_r_episode::oracle::OraclePolicy;
use kitchen_r_episode::policy::Policy;
use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_sim::Assets;
use kitchen_r_worker::job::{JobContext, JobControl, execute_job};
use remote_support::*;

fn ctx() -> &'static JobContext {
    static CTX: OnceLock<JobContext> = OnceLock::new();
    CTX.get_or_init(|| JobContext::load(RemoteConfig::default(), AllowedNetworks::default(), 1).unwrap())
}

fn oracle_server() -> TestServer {
    let assets = Arc::new(Assets::load_default().unwrap());
    let f: PolicyFactory = Arc::new(move || Box::new(OraclePolicy::new(&assets)) as Box<dyn Policy>);
    TestServer::start(f, ServeOptions::default())
}

/// A job for dev-0001 (move, pick, …), its first `steps` plan steps.
pub(crate) fn job(url: &str, mode: pb::EvalMode, steps: u32, privileged: bool) -> pb::Job {
    let data = kitchen_r_core::dataset::Dataset::load(&kitchen_r_core::assets::assets_dir().join("dataset"))
        .unwrap();
    let ins = &data.dev[0];
    pb::Job {
        job_id: 7,
        attempt: 1,
        lease_expires_at_ms: 0,
        run_id: 3,
        episode_key: ins.id.clone(),
        episode: Some(pb::EpisodeSpec {
            scene_id: ins.scene.clone(),
            instruction_id: ins.id.clone(),
            plan: ins.plan.clone(),
            seed: 0,
            mode: mode as i32,
            task_time_limit_s: 120.0,
            actions_executed_per_chunk: 8,
            teleport_on_failure: true,
            max_plan_steps: steps,
            privileged,
            place_targets: ins.place_targets.iter().map(pb::PlaceTarget::from).collect(),
            policy_episode_id: "ep-0123456789abcdef01234567".into(),
            record_video: false,
            video_on_demand: false,
            video_max_bytes: 0,
            privileged_observations: 0,
            grasp_mode: 0,
            live_ros2: false,
        }),
        policy: Some(pb::PolicyEndpoint {
            url: url.to_string(),
            bearer_token: String::new(),
            call_deadline_ms: 20_000,
            startup_deadline_ms: 5_000,
            episode_budget_ms: 300_000,
            max_successive_timeouts: 3,
            ..Default::default()
        }),
        render: None,
    }
}

#[test]
fn a_privileged_online_job_with_the_oracle_succeeds() {
    let server = oracle_server();
    let r = execute_job(
        &job(&server.url(), pb::EvalMode::Online, 2, true),
        ctx(),
        &JobControl::default(),
    );
    assert_eq!(r.platform_error, "", "{}", r.log_tail);
    assert_eq!(r.tasks.len(), 2);
    for t in &r.tasks {
        assert!(t.success && t.completion_time_s > 0.0, "{t:?}\n{}", r.log_tail);
        assert_eq!((t.mse, t.mse_samples), (0.0, 0));
    }
    assert!(
        r.log_tail.contains("episode ep-0123456789abcdef01234567"),
        "{}",
        r.log_tail
    );
    assert!(r.wall_ms > 0);
    // Where the robot went: points tagged by task, one goal per task, the nav goal reached.
    let path = r.path.as_ref().expect("an online episode carries its path");
    let n = path.task.len();
    assert!(n > 10 && n <= 4096, "{n} points");
    assert_eq!((path.base_xy.len(), path.object_xy.len()), (2 * n, 2 * n));
    assert!(path.task.windows(2).all(|w| w[0] <= w[1]), "task tags in order");
    assert_eq!((path.task[0], path.task[n - 1]), (0, 1));
    assert_eq!(path.goals.len(), 2);
    for (i, g) in path.goals.iter().enumerate() {
        assert_eq!(g.index as usize, i);
        assert!(g.x.is_finite() && g.y.is_finite(), "{g:?}");
        if g.kind == "nav" {
            assert_eq!(g.radius, 0.10);
            let d = ((g.end_x - g.x).powi(2) + (g.end_y - g.y).powi(2)).sqrt();
            assert!(d < 0.5, "a successful nav ends near its goal: {g:?}");
        }
    }
    assert!(path.base_xy.iter().all(|v| v.is_finite()));
}

/// Issue 27: the job's grasp mode (the server's `[control] grasp`) is the simulator's for the
/// episode, whatever the worker's own sim.toml says, and the trace records it for the replay.
#[test]
fn the_jobs_grasp_mode_reaches_the_simulator_and_the_trace() {
    use kitchen_r_core::GraspMode;
    let server = oracle_server();
    for mode in GraspMode::ALL {
        let mut job = job(&server.url(), pb::EvalMode::Online, 1, true);
        job.episode.as_mut().unwrap().grasp_mode = pb::GraspMode::from(mode) as i32;
        let done = kitchen_r_worker::job::execute_job_traced(&job, ctx(), &JobControl::default(), true);
        assert_eq!(done.result.platform_error, "", "{}", done.result.log_tail);
        assert!(
            done.result.log_tail.contains(&format!("grasp {mode}")),
            "{}",
            done.result.log_tail
        );
        assert_eq!(done.trace.expect("a trace").run.grasp, mode);
    }
    let spec = job(&server.url(), pb::EvalMode::Online, 1, true).episode.unwrap();
    let mut physical_worker = ctx().sim.clone();
    physical_worker.grasp.mode = GraspMode::Physical;
    // A job from a server that sends no mode is abstract, the only mode such a server ran.
    let cfg = kitchen_r_worker::job::spec::sim_config(&spec, &physical_worker).unwrap();
    assert_eq!(cfg.grasp.mode, GraspMode::Abstract);
    let future = pb::EpisodeSpec {
        grasp_mode: 9,
        ..spec
    };
    assert!(kitchen_r_worker::job::spec::sim_config(&future, &physical_worker).is_err());
}

#[test]
fn an_offline_job_reports_mse_per_task() {
    let server = oracle_server();
    let r = execute_job(
        &job(&server.url(), pb::EvalMode::Offline, 1, true),
        ctx(),
        &JobControl::default(),
    );
    assert_eq!(r.platform_error, "", "{}", r.log_tail);
    let t = &r.tasks[0];
    assert!(t.mse_samples > 0 && t.mse < 1e-3 && !t.success, "{t:?}");
    assert!(r.path.is_none(), "offline episodes carry no path");
    // Without privileged state the oracle cannot predict: every prediction fails, with the reason.
    let r = execute_job(
        &job(&server.url(), pb::EvalMode::Offline, 1, false),
        ctx(),
        &JobControl::default(),
    );
    let t = &r.tasks[0];
    assert_eq!(t.mse, kitchen_r_episode::offline::FAILED_PREDICTION_MSE);
    assert!(t.failure_reason.contains("FailedPrecondition"), "{t:?}");
}

#[test]
fn policy_faults_fail_tasks_and_platform_faults_do_not() {
    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let mut j = job(&format!("http://{free}"), pb::EvalMode::Online, 2, false);
    j.policy.as_mut().unwrap().startup_deadline_ms = 300;
    let r = execute_job(&j, ctx(), &JobControl::default());
    assert_eq!(r.platform_error, "");
    assert_eq!(r.tasks.len(), 2);
    assert!(
        r.tasks
            .iter()
            .all(|t| !t.success && t.failure_reason.starts_with("policy unreachable")),
        "{r:?}"
    );

    // Refusing the offline (MSE) episode costs a failed prediction at every decision point the
    // expert passes, exactly like answering badly: dodging never improves MSE.
    let mut j = job(&format!("http://{free}"), pb::EvalMode::Offline, 2, false);
    j.policy.as_mut().unwrap().startup_deadline_ms = 300;
    let r = execute_job(&j, ctx(), &JobControl::default());
    assert_eq!(r.platform_error, "", "{}", r.log_tail);
    assert_eq!(r.tasks.len(), 2);
    for t in &r.tasks {
        assert!(t.mse_samples > 1, "{t:?}");
        assert_eq!(t.mse, kitchen_r_episode::offline::FAILED_PREDICTION_MSE, "{t:?}");
        assert!(t.failure_reason.contains("policy unreachable"), "{t:?}");
    }

    let r = execute_job(
        &job("http://192.168.3.4:50051", pb::EvalMode::Online, 1, false),
        ctx(),
        &JobControl::default(),
    );
    assert!(r.tasks[0].failure_reason.contains("private"), "{r:?}");

    // A job without its place targets cannot be simulated: a platform fault, never a score.
    let mut j = job("http://127.0.0.1:1", pb::EvalMode::Online, 0, false);
    j.episode.as_mut().unwrap().place_targets.clear();
    let r = execute_job(&j, ctx(), &JobControl::default());
    assert!(
        r.tasks.is_empty() && r.platform_error.contains("place targets"),
        "{r:?}"
    );

    let mut j = job("http://127.0.0.1:1", pb::EvalMode::Unspecified, 0, false);
    j.episode.as_mut().unwrap().mode = 0;
    assert!(
        execute_job(&j, ctx(), &JobControl::default())
            .platform_error
            .contains("mode")
    );
}

#[test]
fn a_cancelled_job_is_a_platform_error_not_a_score() {
    let server = TestServer::start(still(), ServeOptions::default());
    let control = JobControl::default();
    control.cancel("worker shutting down");
    let r = execute_job(
        &job(&server.url(), pb::EvalMode::Online, 2, false),
        ctx(),
        &control,
    );
    assert!(r.tasks.is_empty(), "{r:?}");
    assert_eq!(r.platform_error, "cancelled: worker shutting down");
}

#[test]
fn local_eval_of_an_endpoint_gives_the_workers_numbers() {
    use kitchen_r_worker::job::local::{LocalSettings, Mode, evaluate_endpoint};
    let server = oracle_server();
    let data = kitchen_r_core::dataset::Dataset::load(&kitchen_r_core::assets::assets_dir().join("dataset"))
        .unwrap();
    let s = LocalSettings {
        mode: Mode::Online,
        seed: 0,
        run: kitchen_r_episode::runner::RunOptions {
            max_tasks: Some(2),
            ..Default::default()
        },
        teleport_on_failure: true,
        bearer_token: None,
        key_map: None,
        privileged: true,
        privileged_observations: None,
        jobs: 4,
        record: None,
        trace: None,
        watch: None,
        grasp: None,
        max_batch: 0,
        batch_gather_ms: 0.0,
    };
    let local = evaluate_endpoint(
        &server.url(),
        kitchen_r_core::dataset::Split::Dev,
        &data.dev[..1],
        &s,
        &mut |_| {},
    )
    .unwrap();
    // The oracle announces max concurrency 1: the local run honours it.
    assert_eq!((local.jobs, local.sr), (1, Some(1.0)), "{local:?}");
    let worker = execute_job(
        &job(&server.url(), pb::EvalMode::Online, 2, true),
        ctx(),
        &JobControl::default(),
    );
    let times = |v: Vec<f64>| v.into_iter().map(f64::to_bits).collect::<Vec<_>>();
    assert_eq!(
        times(
            local.episodes[0]
                .tasks
                .iter()
                .map(|t| t.completion_time_s)
                .collect()
        ),
        times(worker.tasks.iter().map(|t| t.completion_time_s).collect())
    );
}
