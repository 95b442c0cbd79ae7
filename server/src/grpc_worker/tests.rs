use kitchen_r_core::dataset::Split;
use tonic::Code;

use super::*;
use crate::testutil::{FakeProbe, WORKER, fixture};

fn with_token<T>(msg: T, token: &str) -> Request<T> {
    let mut req = Request::new(msg);
    req.metadata_mut()
        .insert("authorization", format!("Bearer {token}").parse().unwrap());
    req
}

fn lease_req() -> pb::LeaseRequest {
    pb::LeaseRequest {
        worker_id: "host-1/42".into(),
        max_jobs: 8,
        wait_ms: 0,
        max_renders: 0,
    }
}

#[tokio::test]
async fn unauthenticated_workers_are_refused() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let mut client = f.worker_client().await;
    let e = client.lease(lease_req()).await.unwrap_err();
    assert_eq!(e.code(), Code::Unauthenticated);
    let e = client.lease(with_token(lease_req(), "wrong")).await.unwrap_err();
    assert_eq!(e.code(), Code::Unauthenticated);
    let e = client
        .heartbeat(pb::HeartbeatRequest::default())
        .await
        .unwrap_err();
    assert_eq!(e.code(), Code::Unauthenticated);
    let e = client.release(pb::ReleaseRequest::default()).await.unwrap_err();
    assert_eq!(e.code(), Code::Unauthenticated);
}

#[tokio::test]
async fn lease_heartbeat_and_report_over_grpc() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.dev_episodes = 1;
        c.control.seed = 1234;
    })
    .await;
    let mut client = f.worker_client().await;
    let token = f.team("alpha").await;
    let mut reference = f.request(Split::Dev);
    reference.token = Some("participant-secret".into());
    f.state
        .register_policy(&f.caller(&token).await, reference)
        .await
        .unwrap();

    let empty = client
        .lease(with_token(
            pb::LeaseRequest {
                max_jobs: 0,
                ..lease_req()
            },
            WORKER,
        ))
        .await;
    assert_eq!(empty.unwrap_err().code(), Code::InvalidArgument);
    let jobs = client
        .lease(with_token(lease_req(), WORKER))
        .await
        .unwrap()
        .into_inner()
        .jobs;
    assert_eq!(jobs.len(), 2);
    let gt = &f.state.content().ground_truth(Split::Dev)[0];
    let job = &jobs[0];
    let ep = job.episode.clone().unwrap();
    assert_eq!(
        (ep.scene_id.as_str(), ep.instruction_id.as_str()),
        (gt.scene.as_str(), gt.id.as_str())
    );
    assert_eq!(ep.plan, gt.plan);
    assert_eq!((ep.seed, ep.mode), (1234, pb::EvalMode::Online as i32));
    assert_eq!((ep.task_time_limit_s, ep.actions_executed_per_chunk), (120.0, 8));
    assert!(ep.teleport_on_failure && !ep.privileged);
    assert_eq!(
        jobs[1].episode.as_ref().unwrap().mode,
        pb::EvalMode::Offline as i32
    );
    assert_eq!(jobs[1].episode_key, format!("{}/offline", gt.id));
    let policy = job.policy.clone().unwrap();
    assert_eq!(policy.url, "http://127.0.0.1:50099");
    assert_eq!(policy.bearer_token, "participant-secret");
    assert_eq!(
        (policy.call_deadline_ms, policy.startup_deadline_ms),
        (10_000, 30_000)
    );
    assert_eq!(
        (policy.episode_budget_ms, policy.max_successive_timeouts),
        (600_000, 3)
    );
    // Contract v1.1: the organiser's minimum execution count and chunk tolerances travel too.
    assert_eq!(
        (
            policy.min_actions_executed_per_chunk,
            policy.quat_norm_tolerance,
            policy.gripper_margin
        ),
        (1, Some(0.1), Some(0.05))
    );
    assert_eq!(job.attempt, 1);

    let hb = pb::HeartbeatRequest {
        worker_id: "host-1/42".into(),
        job_id: job.job_id,
        attempt: 1,
        tasks_done: 0,
        ..Default::default()
    };
    let out = client
        .heartbeat(with_token(hb.clone(), WORKER))
        .await
        .unwrap()
        .into_inner();
    assert!(!out.cancelled && out.lease_expires_at_ms >= job.lease_expires_at_ms);
    let stale = pb::HeartbeatRequest { attempt: 2, ..hb };
    assert!(
        client
            .heartbeat(with_token(stale, WORKER))
            .await
            .unwrap()
            .into_inner()
            .cancelled
    );

    for j in &jobs {
        let report = pb::ReportResultRequest {
            worker_id: "host-1/42".into(),
            job_id: j.job_id,
            attempt: j.attempt,
            run_id: j.run_id,
            episode_key: j.episode_key.clone(),
            result: Some(pb::EpisodeResult {
                tasks: vec![pb::TaskResult {
                    index: 0,
                    step: gt.plan[0].clone(),
                    success: true,
                    completion_time_s: 4.0,
                    mse: 0.5,
                    mse_samples: 3,
                    ..Default::default()
                }],
                log_tail: "done".into(),
                wall_ms: 12,
                // Every report carries a path; only the online episode's is kept.
                path: Some(pb::EpisodePath {
                    base_xy: vec![1.0, 1.0, 1.5, 1.2],
                    object_xy: vec![f32::NAN; 4],
                    task: vec![0, 0],
                    goals: Vec::new(),
                }),
                ..Default::default()
            }),
        };
        let out = client
            .report_result(with_token(report.clone(), WORKER))
            .await
            .unwrap()
            .into_inner();
        assert!(out.accepted && !out.duplicate);
        let again = client
            .report_result(with_token(report, WORKER))
            .await
            .unwrap()
            .into_inner();
        assert!(again.accepted && again.duplicate);
    }
    let run = f
        .state
        .get_submission(&f.caller(&token).await, 1)
        .await
        .unwrap()
        .latest_run
        .unwrap();
    let evaluation = run.evaluation.unwrap();
    assert_eq!(evaluation.state, "finished");
    let plots: Vec<_> = (evaluation.episodes.iter())
        .map(|e| (e.mode.as_str(), e.plot_url.is_some()))
        .collect();
    assert_eq!(plots, vec![("online", true), ("offline", false)], "{plots:?}");
    let sr = run.scores.sr.unwrap();
    assert!((sr - 1.0 / gt.plan.len() as f64).abs() < 1e-12);
    // Only task 0 was reported: each unreported task of the offline episode is one failed
    // prediction, so a worker (or policy) that stops early never lowers the MSE.
    let missing = (gt.plan.len() - 1) as f64;
    let expected = (0.5 * 3.0 + kitchen_r_core::metrics::FAILED_PREDICTION_MSE * missing) / (3.0 + missing);
    assert!(
        (run.scores.mse.unwrap() - expected).abs() < 1e-12,
        "{:?}",
        run.scores
    );
}

#[tokio::test]
async fn reference_runs_reach_workers_as_privileged() {
    let f = fixture(FakeProbe::ok(8), |c| c.control.dev_episodes = 1).await;
    let mut client = f.worker_client().await;
    let mut reference = f.request(Split::Dev);
    reference.reference = true;
    f.state
        .register_policy(&f.caller(crate::testutil::ADMIN).await, reference)
        .await
        .unwrap();
    let jobs = client
        .lease(with_token(lease_req(), WORKER))
        .await
        .unwrap()
        .into_inner()
        .jobs;
    assert!(jobs.iter().all(|j| j.episode.as_ref().unwrap().privileged));
}

/// `[live] ros2` (docs/twin/live.md) reaches the workers with the online dev-split jobs only: never
/// with a test-split job (its topics would show the hidden plan), nor an offline one; and with
/// the setting off, with none.
#[tokio::test]
async fn live_ros2_is_sent_with_online_dev_jobs_only() {
    for on in [true, false] {
        let f = fixture(FakeProbe::ok(64), |c| {
            c.control.dev_episodes = 1;
            c.quota.concurrent_runs = 0;
            c.live.ros2 = on;
        })
        .await;
        let caller = f.caller(&f.team("alpha").await).await;
        for split in [Split::Dev, Split::Test] {
            f.state.register_policy(&caller, f.request(split)).await.unwrap();
        }
        let mut client = f.worker_client().await;
        let mut seen = std::collections::BTreeMap::<(bool, i32), (usize, usize)>::new();
        loop {
            let req = with_token(
                pb::LeaseRequest {
                    max_jobs: 64,
                    ..lease_req()
                },
                WORKER,
            );
            let jobs = client.lease(req).await.unwrap().into_inner().jobs;
            if jobs.is_empty() {
                break;
            }
            for e in jobs.iter().map(|j| j.episode.as_ref().unwrap()) {
                let test = f.state.content().is_test(&e.instruction_id);
                let n = seen.entry((test, e.mode)).or_default();
                n.0 += 1;
                n.1 += usize::from(e.live_ros2);
            }
        }
        let online = pb::EvalMode::Online as i32;
        for (&(test, mode), &(jobs, live)) in &seen {
            let want = if on && !test && mode == online { jobs } else { 0 };
            assert_eq!(live, want, "test split {test}, mode {mode}: {seen:?}");
        }
        assert!(
            seen.contains_key(&(true, online)) && seen.contains_key(&(false, online)),
            "{seen:?}"
        );
    }
}
