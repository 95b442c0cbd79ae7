//! Issue 23 over real gRPC: reports checked against the leased job's plan, and the endpoint-
//! controlled text of a report stored capped.

use kitchen_r_core::dataset::Split;
use tonic::Code;

use super::*;
use crate::testutil::{FakeProbe, Fixture, WORKER, fixture};

type Client = pb::worker_client::WorkerClient<tonic::transport::Channel>;

fn with_token<T>(msg: T) -> Request<T> {
    let mut req = Request::new(msg);
    req.metadata_mut()
        .insert("authorization", format!("Bearer {WORKER}").parse().unwrap());
    req
}

/// A dev run of one instruction leased over gRPC: its online and offline jobs.
async fn leased(f: &Fixture, client: &mut Client) -> (pb::Job, pb::Job) {
    let token = f.team("alpha").await;
    (f.state)
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap();
    let lease = pb::LeaseRequest {
        worker_id: "w1".into(),
        max_jobs: 8,
        wait_ms: 0,
        max_renders: 0,
    };
    let jobs = client.lease(with_token(lease)).await.unwrap().into_inner().jobs;
    assert_eq!(jobs.len(), 2);
    (jobs[0].clone(), jobs[1].clone())
}

/// A report of `job` with these task results.
fn report(job: &pb::Job, tasks: Vec<pb::TaskResult>) -> pb::ReportResultRequest {
    pb::ReportResultRequest {
        worker_id: "w1".into(),
        job_id: job.job_id,
        attempt: job.attempt,
        run_id: job.run_id,
        episode_key: job.episode_key.clone(),
        result: Some(pb::EpisodeResult {
            tasks,
            log_tail: "done".into(),
            wall_ms: 5,
            ..Default::default()
        }),
    }
}

/// Task `index` of `job`'s plan, failed.
fn task(job: &pb::Job, index: u32) -> pb::TaskResult {
    let plan = &job.episode.as_ref().unwrap().plan;
    pb::TaskResult {
        index,
        step: plan.get(index as usize).cloned().unwrap_or_default(),
        failure_reason: "timeout".into(),
        ..Default::default()
    }
}

async fn job_state(f: &Fixture, id: i64) -> (String, i64, i64) {
    sqlx::query_as(
        "SELECT j.state, j.attempt, (SELECT COUNT(*) FROM episode_results e WHERE e.job_id = j.id)
         FROM jobs j WHERE j.id = ?",
    )
    .bind(id)
    .fetch_one(f.state.pool())
    .await
    .unwrap()
}

#[tokio::test]
async fn a_report_that_does_not_fit_the_leased_plan_is_refused_and_the_lease_kept() {
    let f = fixture(FakeProbe::ok(8), |c| c.control.dev_episodes = 1).await;
    let mut client = f.worker_client().await;
    let (online, offline) = leased(&f, &mut client).await;
    let n = online.episode.as_ref().unwrap().plan.len() as u32;
    let mut wrong_step = task(&online, 0);
    wrong_step.step = "dance".into();
    let too_many: Vec<pb::TaskResult> = (0..=n).map(|i| task(&online, i % n)).collect();
    let many_samples = pb::TaskResult {
        mse: 0.1,
        mse_samples: 4_000_000_000,
        ..task(&offline, 0)
    };
    let high_mse = pb::TaskResult {
        mse: 100.0,
        mse_samples: 3,
        ..task(&offline, 0)
    };
    let refused = [
        (&online, vec![task(&online, 99)], "task index 99 is out of range"),
        (
            &online,
            vec![task(&online, 0), task(&online, 0)],
            "task index 0 is reported twice",
        ),
        (&online, too_many, "task results for an episode of"),
        (&online, vec![wrong_step], "names step \"dance\""),
        (&offline, vec![many_samples], "MSE samples"),
        (&offline, vec![high_mse], "above the failed-prediction MSE"),
    ];
    for (job, tasks, why) in refused {
        let e = client
            .report_result(with_token(report(job, tasks)))
            .await
            .unwrap_err();
        assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
        assert!(e.message().contains(why), "{why}: {}", e.message());
        // Nothing recorded; the lease is as it was, so a good report still goes through.
        assert_eq!(job_state(&f, job.job_id).await, ("leased".into(), 1, 0));
    }
    for job in [&online, &offline] {
        let ok = report(job, (0..n).map(|i| task(job, i)).collect());
        let out = client.report_result(with_token(ok)).await.unwrap().into_inner();
        assert!(out.accepted && !out.duplicate);
        assert_eq!(job_state(&f, job.job_id).await, ("done".into(), 1, 1));
    }
}

#[tokio::test]
async fn endpoint_controlled_text_is_stored_capped() {
    let f = fixture(FakeProbe::ok(8), |c| c.control.dev_episodes = 1).await;
    let mut client = f.worker_client().await;
    let (online, offline) = leased(&f, &mut client).await;
    // A policy's 6 KB error message, as a failure reason and in the log tail.
    let blurb = format!(
        "Act: the policy answered with an error (status Unknown: {})",
        "é".repeat(6 << 10)
    );
    let mut req = report(
        &online,
        vec![pb::TaskResult {
            failure_reason: blurb.clone(),
            ..task(&online, 0)
        }],
    );
    req.result.as_mut().unwrap().log_tail = format!("start\ntask 0 failed: {blurb}\nend");
    client.report_result(with_token(req)).await.unwrap();
    let (tasks, log): (String, String) =
        sqlx::query_as("SELECT tasks, log_tail FROM episode_results WHERE job_id = ?")
            .bind(online.job_id)
            .fetch_one(f.state.pool())
            .await
            .unwrap();
    let tasks: Vec<TaskOutcome> = serde_json::from_str(&tasks).unwrap();
    let reason = &tasks[0].failure_reason;
    assert_eq!(reason.chars().count(), 512, "{reason}");
    assert!(reason.starts_with("Act: the policy answered") && reason.ends_with('…'));
    let lines: Vec<usize> = log.lines().map(|l| l.chars().count()).collect();
    assert_eq!(lines, vec![5, 1024, 3], "{log}");
    // A platform error quoting endpoint text: the job's last_error is capped too.
    let mut req = report(&offline, Vec::new());
    req.result.as_mut().unwrap().platform_error = blurb;
    client.report_result(with_token(req)).await.unwrap();
    let last: String = sqlx::query_scalar("SELECT last_error FROM jobs WHERE id = ?")
        .bind(offline.job_id)
        .fetch_one(f.state.pool())
        .await
        .unwrap();
    assert!(last.chars().count() < 600 && last.ends_with('…'), "{last}");
}
