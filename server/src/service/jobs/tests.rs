use kitchen_r_core::dataset::Split;

use super::*;
use crate::testutil::{ADMIN, FakeProbe, Fixture, WORKER, fixture};

async fn registered(f: &Fixture) -> (String, i64) {
    let token = f.team("alpha").await;
    let done = f
        .state
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap();
    (token, done.id)
}

async fn run_state(f: &Fixture, token: &str, id: i64) -> crate::service::PolicyRunView {
    let view = f.state.get_submission(&f.caller(token).await, id).await.unwrap();
    view.latest_run.unwrap().evaluation.unwrap()
}

#[tokio::test]
async fn workers_must_present_the_worker_token() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let lease = async |token: Option<&str>, worker: &str, max: u32| {
        let cred = f.state.caller(token).await?.worker()?;
        f.state.lease(cred, worker, max, 0).await
    };
    let code = |r: Result<Vec<LeasedJob>, ServiceError>| r.unwrap_err().code();
    assert_eq!(code(lease(None, "w", 1).await), "missing_token");
    assert_eq!(code(lease(Some("nope"), "w", 1).await), "bad_token");
    assert_eq!(code(lease(Some(ADMIN), "w", 1).await), "bad_token");
    assert_eq!(code(lease(Some(WORKER), "w", 0).await), "bad_request");
    assert_eq!(code(lease(Some(WORKER), "", 1).await), "bad_request");
}

#[tokio::test]
async fn claims_never_exceed_the_policys_max_concurrency() {
    let f = fixture(FakeProbe::ok(2), |_| {}).await;
    registered(&f).await;
    let first = f.lease("w1", 64).await;
    assert_eq!(first.len(), 2, "max_concurrency 2");
    assert!(f.lease("w2", 64).await.is_empty());
    let job = &first[0];
    assert_eq!(job.attempt, 1);
    assert_eq!(job.spec.endpoint.url, "http://127.0.0.1:50099");
    let r = f.report("w1", job, |_| true, 0.0);
    assert!(f.state.report_result(f.worker().await, r).await.unwrap().accepted);
    let next = f.lease("w2", 64).await;
    assert_eq!(next.len(), 1, "one slot freed");
    assert!(next[0].id > first[1].id, "oldest queued job first");
}

#[tokio::test]
async fn long_poll_wakes_up_when_a_slot_frees() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    registered(&f).await;
    let job = f.lease("w1", 1).await.remove(0);
    let (state, cred) = (f.state.clone(), f.worker().await);
    let waiter = tokio::spawn(async move { state.lease(cred, "w2", 1, 10_000).await.unwrap() });
    tokio::time::sleep(Duration::from_millis(50)).await;
    let started = std::time::Instant::now();
    f.state
        .report_result(f.worker().await, f.report("w1", &job, |_| true, 0.0))
        .await
        .unwrap();
    let got = waiter.await.unwrap();
    assert_eq!(got.len(), 1);
    assert!(started.elapsed() < Duration::from_secs(5));
}

#[tokio::test]
async fn heartbeats_extend_only_the_current_lease() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    registered(&f).await;
    let job = f.lease("w1", 1).await.remove(0);
    let hb = f
        .state
        .heartbeat(f.worker().await, "w1", job.id, job.attempt)
        .await
        .unwrap();
    assert!(hb.lease_expires_at_ms.unwrap() >= job.lease_expires_at_ms);
    let other = f
        .state
        .heartbeat(f.worker().await, "w2", job.id, job.attempt)
        .await
        .unwrap();
    assert_eq!(other.lease_expires_at_ms, None, "another owner is told to stop");
    let stale = f
        .state
        .heartbeat(f.worker().await, "w1", job.id, job.attempt + 1)
        .await
        .unwrap();
    assert_eq!(stale.lease_expires_at_ms, None);
}

#[tokio::test]
async fn expired_lease_is_requeued_and_a_stale_attempt_refused_then_duplicates_count_once() {
    let f = fixture(FakeProbe::ok(1), |c| c.control.lease_s = 1).await;
    let (token, id) = registered(&f).await;
    let first = f.lease("w1", 1).await.remove(0);
    assert_eq!(
        f.state.reap_expired(now_ms()).await.unwrap(),
        ReapReport::default()
    );
    let reaped = f.state.reap_expired(now_ms() + 5_000).await.unwrap();
    assert_eq!((reaped.requeued, reaped.failed), (1, 0));
    let again = f.lease("w2", 1).await.remove(0);
    assert_eq!((again.id, again.attempt), (first.id, 2));
    // The worker that lost the lease reports late: refused, nothing recorded.
    let late = f
        .state
        .report_result(f.worker().await, f.report("w1", &first, |_| true, 0.0))
        .await
        .unwrap();
    assert_eq!(
        late,
        ReportOutcome {
            accepted: false,
            duplicate: false
        }
    );
    assert!(
        f.state
            .heartbeat(f.worker().await, "w1", first.id, 1)
            .await
            .unwrap()
            .lease_expires_at_ms
            .is_none()
    );
    let r = f.report("w2", &again, |_| true, 0.0);
    let ok = f.state.report_result(f.worker().await, r.clone()).await.unwrap();
    assert_eq!(
        ok,
        ReportOutcome {
            accepted: true,
            duplicate: false
        }
    );
    let dup = f.state.report_result(f.worker().await, r).await.unwrap();
    assert_eq!(
        dup,
        ReportOutcome {
            accepted: true,
            duplicate: true
        }
    );
    let eval = run_state(&f, &token, id).await;
    assert_eq!((eval.state, eval.episodes_done), ("running", 1));
    assert!(eval.retrying.is_empty(), "the retried episode is recorded now");
    assert_eq!(eval.episodes[0].attempt, 2);
}

#[tokio::test]
async fn platform_errors_requeue_then_fail_after_max_attempts_and_the_run_still_finishes() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.max_attempts = 2;
        c.control.dev_episodes = 1;
        c.control.offline_mse = false;
    })
    .await;
    let (token, id) = registered(&f).await;
    for attempt in 1..=2 {
        if attempt == 2 {
            let retrying = run_state(&f, &token, id).await.retrying;
            assert_eq!(retrying.len(), 1);
            assert!(
                retrying[0]
                    .last_error
                    .contains("attempt 1: platform error: simulator crashed")
            );
        }
        let job = f.lease("w1", 8).await.remove(0);
        assert_eq!(job.attempt, attempt);
        let mut r = f.report("w1", &job, |_| true, 0.0);
        r.platform_error = "simulator crashed".into();
        assert!(f.state.report_result(f.worker().await, r).await.unwrap().accepted);
    }
    assert!(f.lease("w1", 8).await.is_empty());
    let view = f.state.get_submission(&f.caller(&token).await, id).await.unwrap();
    let run = view.latest_run.unwrap();
    let eval = run.evaluation.unwrap();
    assert_eq!(eval.state, "platform_failed");
    let failure = eval.episodes[0].failure.clone().unwrap();
    assert!(
        failure.contains("gave up after 2 attempts") && failure.contains("simulator crashed"),
        "{failure}"
    );
    assert_eq!(run.scores.sr, Some(0.0));
    // A run the platform could not evaluate gives its quota back.
    let used = crate::store::count_submissions_since(f.state.pool(), 1, Split::Dev, 0)
        .await
        .unwrap();
    assert_eq!(used, 0);
}

#[tokio::test]
async fn expired_leases_fail_after_max_attempts() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.max_attempts = 1;
        c.control.dev_episodes = 1;
    })
    .await;
    let (token, id) = registered(&f).await;
    let jobs = f.lease("w1", 8).await;
    assert_eq!(jobs.len(), 2);
    let online = jobs
        .iter()
        .find(|j| !j.episode_key.ends_with("/offline"))
        .unwrap();
    let r = f.report("w1", online, |_| true, 0.0);
    f.state.report_result(f.worker().await, r).await.unwrap();
    let reaped = f.state.reap_expired(now_ms() + 3_600_000).await.unwrap();
    assert_eq!((reaped.requeued, reaped.failed, reaped.runs_finished), (0, 1, 1));
    let run = f
        .state
        .get_submission(&f.caller(&token).await, id)
        .await
        .unwrap()
        .latest_run
        .unwrap();
    assert_eq!(run.evaluation.unwrap().state, "finished");
    assert_eq!((run.scores.sr, run.scores.mse), (Some(1.0), None));
}

#[tokio::test]
async fn a_finished_run_is_scored_once_with_sr_and_mse() {
    let f = fixture(FakeProbe::ok(64), |c| c.control.dev_episodes = 2).await;
    let (token, id) = registered(&f).await;
    let jobs = f.lease("w1", 64).await;
    assert_eq!(jobs.len(), 4);
    for (i, job) in jobs.iter().enumerate() {
        // Instruction 0 succeeds on its first task only; instruction 1 on every task.
        let first = job.spec.instruction_id == f.state.content().ground_truth(Split::Dev)[0].id;
        let r = f.report("w1", job, |j| !first || j == 0, 0.5 * (i as f64 + 1.0));
        f.state.report_result(f.worker().await, r).await.unwrap();
    }
    let dev = f.state.content().ground_truth(Split::Dev);
    let expected_sr = (1.0 / dev[0].plan.len() as f64 + 1.0) / 2.0;
    let run = f
        .state
        .get_submission(&f.caller(&token).await, id)
        .await
        .unwrap()
        .latest_run
        .unwrap();
    let sr = run.scores.sr.unwrap();
    assert!((sr - expected_sr).abs() < 1e-12, "{sr} vs {expected_sr}");
    // Offline MSEs were 0.5·(i+1) for the offline jobs (indices 1 and 3), weighted by tasks.
    let (n0, n1) = (dev[0].plan.len() as f64, dev[1].plan.len() as f64);
    let expected_mse = (1.0 * n0 + 2.0 * n1) / (n0 + n1);
    assert!((run.scores.mse.unwrap() - expected_mse).abs() < 1e-12);
    let eval = run.evaluation.unwrap();
    assert_eq!(
        (eval.state, eval.episodes_done, eval.episodes_total),
        ("finished", 4, 4)
    );
    assert_eq!(eval.episodes[0].failure_reasons, vec!["timeout".to_string()]);
    assert!(run.scores.m.is_none());
}

#[tokio::test]
async fn an_integrated_run_recomputes_em_from_the_linked_plans() {
    let f = fixture(FakeProbe::ok(64), |c| c.control.dev_episodes = 2).await;
    let token = f.team("alpha").await;
    let dev = f.state.content().ground_truth(Split::Dev).to_vec();
    // Instruction 0 exactly right, instruction 1 right on its first step only.
    let lines = format!(
        "{}\n{}\n",
        serde_json::json!({"id": dev[0].id, "plan": dev[0].plan}),
        serde_json::json!({"id": dev[1].id, "plan": [dev[1].plan[0].clone()]}),
    );
    let plans = f
        .state
        .submit_plans(&f.team_of(&token).await, Split::Dev, lines.as_bytes())
        .await
        .unwrap()
        .id;
    let mut req = f.request(Split::Dev);
    req.plans = Some(plans);
    let id = f
        .state
        .register_policy(&f.caller(&token).await, req)
        .await
        .unwrap()
        .id;
    for job in f.lease("w1", 64).await {
        // Every task succeeds online; offline MSE 0.25 everywhere.
        let r = f.report("w1", &job, |_| true, 0.25);
        f.state.report_result(f.worker().await, r).await.unwrap();
    }
    let (n0, n1) = (dev[0].plan.len() as f64, dev[1].plan.len() as f64);
    let em = (1.0 + 1.0 / n1) / 2.0;
    // M: instruction 0 = 2 per task; instruction 1 = (2 + 1·(n1-1)) / n1.
    let m = (2.0 + (2.0 + (n1 - 1.0)) / n1) / 2.0;
    let p = 1.0 / em + 0.25;
    let run = f
        .state
        .get_submission(&f.caller(&token).await, id)
        .await
        .unwrap()
        .latest_run
        .unwrap();
    let s = run.scores;
    assert!((s.sr.unwrap() - 1.0).abs() < 1e-12);
    assert!((s.m.unwrap() - m).abs() < 1e-12, "{s:?} m={m}");
    assert!((s.p.unwrap() - p).abs() < 1e-12, "{s:?} p={p}");
    assert!(n0 > 0.0);
    let board = f
        .state
        .leaderboard(crate::leaderboard::Track::Integrated, Split::Dev)
        .await
        .unwrap();
    assert_eq!(board.rows.len(), 1);
    assert_eq!(board.rows[0].scores.m, s.m);
    assert!(
        (s.em.unwrap() - em).abs() < 1e-12,
        "integrated runs show their EM: {s:?}"
    );

    // A rescore recomputes M and P from the recorded episodes as a new run, episodes kept.
    let report = f.state.rescore_all(f.admin().await).await.unwrap();
    assert_eq!(
        (report.rescored, report.policy_runs_rescored),
        (1, 1),
        "{report:?}"
    );
    let view = f.state.get_submission(&f.caller(&token).await, id).await.unwrap();
    assert_eq!(view.runs, 2);
    let run2 = view.latest_run.unwrap();
    assert_ne!(run2.id, run.id);
    assert_eq!(run2.scores, s);
    let eval = run2.evaluation.unwrap();
    assert_eq!(eval.rescored_from_run, Some(run.id));
    assert_eq!(
        eval.episodes.len(),
        4,
        "the rescored run shows the episodes it was computed from"
    );

    // An instruction changed under the recorded episodes: flagged, scores kept, nothing added.
    sqlx::query("UPDATE jobs SET spec = json_set(spec, '$.place_targets[0][0]', -1.0)")
        .execute(f.state.pool())
        .await
        .unwrap();
    let report = f.state.rescore_all(f.admin().await).await.unwrap();
    assert_eq!(report.policy_runs_rescored, 0, "{report:?}");
    assert_eq!(report.needs_resimulation.len(), 1, "{report:?}");
    assert!(
        report.needs_resimulation[0].error.contains("changed"),
        "{report:?}"
    );
    let view = f.state.get_submission(&f.caller(&token).await, id).await.unwrap();
    assert_eq!(view.runs, 2);
    let run2 = view.latest_run.unwrap();
    assert_eq!(run2.scores, s);
    assert!(run2.evaluation.unwrap().needs_resimulation);

    // The organiser has it simulated again: a new run on the same submission, current specs.
    let again = f.state.resimulate(f.admin().await, id).await.unwrap();
    assert_eq!((again.id, again.episodes), (id, 4));
    assert!(
        f.state.resimulate(f.admin().await, id).await.is_err(),
        "still evaluating"
    );
    for job in f.lease("w2", 64).await {
        assert_eq!(job.run_id, again.run_id);
        let r = f.report("w2", &job, |_| true, 0.25);
        f.state.report_result(f.worker().await, r).await.unwrap();
    }
    let view = f.state.get_submission(&f.caller(&token).await, id).await.unwrap();
    let run3 = view.latest_run.unwrap();
    assert_eq!(run3.id, again.run_id);
    assert_eq!(run3.scores, s);
    let eval = run3.evaluation.unwrap();
    assert!(!eval.needs_resimulation && eval.state == "finished");
    assert_eq!(
        f.state
            .rescore_all(f.admin().await)
            .await
            .unwrap()
            .policy_runs_rescored,
        1
    );
}

#[tokio::test]
async fn shutdown_ends_long_polls_at_once() {
    let f = fixture(FakeProbe::ok(1), |_| {}).await;
    let (state, cred) = (f.state.clone(), f.worker().await);
    let started = std::time::Instant::now();
    let waiter = tokio::spawn(async move { state.lease(cred, "w", 1, 30_000).await.unwrap() });
    tokio::time::sleep(Duration::from_millis(50)).await;
    f.state.begin_shutdown();
    assert!(waiter.await.unwrap().is_empty());
    assert!(started.elapsed() < Duration::from_secs(5));
    registered(&f).await;
    assert!(
        f.lease("w", 1).await.is_empty(),
        "nothing is leased while stopping"
    );
}

#[tokio::test]
async fn a_restarted_server_resumes_the_run_from_sqlite() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.dev_episodes = 1;
        c.control.offline_mse = false;
    })
    .await;
    let (token, id) = registered(&f).await;
    let lost = f.lease("w1", 8).await.remove(0);
    // The first process dies with the lease held; the next one reaps it once it expires.
    let restarted = f.reopen(FakeProbe::ok(8)).await;
    let reaped = restarted.reap_expired(now_ms() + 3_600_000).await.unwrap();
    assert_eq!(reaped.requeued, 1);
    let job = restarted
        .lease(f.worker().await, "w2", 8, 0)
        .await
        .unwrap()
        .remove(0);
    assert_eq!((job.id, job.attempt), (lost.id, 2));
    restarted
        .report_result(f.worker().await, f.report("w2", &job, |_| true, 0.0))
        .await
        .unwrap();
    let run = restarted
        .get_submission(&f.caller(&token).await, id)
        .await
        .unwrap()
        .latest_run
        .unwrap();
    assert_eq!(
        (run.evaluation.unwrap().state, run.scores.sr),
        ("finished", Some(1.0))
    );
}

/// Team `name` registers a dev run of its first `episodes` instructions (an online and an
/// offline job each); returns the run's job count.
async fn register_team(f: &Fixture, name: &str, episodes: u32) {
    let token = f.team(name).await;
    let mut req = f.request(Split::Dev);
    req.episodes = Some(episodes);
    f.state
        .register_policy(&f.caller(&token).await, req)
        .await
        .unwrap();
}

#[tokio::test]
async fn a_later_small_run_is_not_starved_by_a_big_one() {
    // Fair sharing (docs/control-track-server.md, Lease): team A queues 40 episodes
    // (max_concurrency 64), team B then 2; two slots. Before, B waited for all of A's backlog.
    let f = fixture(FakeProbe::ok(64), |c| c.control.dev_episodes = 20).await;
    register_team(&f, "alpha", 20).await;
    let a1 = f.lease("slot-1", 1).await.remove(0);
    let a2 = f.lease("slot-2", 1).await.remove(0);
    assert_eq!(a1.run_id, a2.run_id);
    register_team(&f, "bravo", 1).await;
    // A's first episode ends: the next lease call takes B's first, not A's third.
    let r = f.report("slot-1", &a1, |_| true, 0.0);
    assert!(f.state.report_result(f.worker().await, r).await.unwrap().accepted);
    let b1 = f.lease("slot-1", 1).await.remove(0);
    assert_ne!(b1.run_id, a1.run_id, "team B's first episode goes next");
    // Each team has one in flight now: A's second slot goes back to A (fewest in flight, then
    // the oldest job), so both runs progress.
    let r = f.report("slot-2", &a2, |_| true, 0.0);
    assert!(f.state.report_result(f.worker().await, r).await.unwrap().accepted);
    let next = f.lease("slot-2", 1).await.remove(0);
    assert_eq!(next.run_id, a1.run_id);
    // One claim of several jobs deals them out round-robin: B's last job is in it.
    let many = f.lease("big", 4).await;
    assert_eq!(many.len(), 4);
    assert_eq!(
        many.iter().filter(|j| j.run_id == b1.run_id).count(),
        1,
        "B has one job left and gets it in the first claim"
    );
}

#[tokio::test]
async fn a_team_never_has_more_than_its_cap_in_flight() {
    let f = fixture(FakeProbe::ok(64), |c| {
        c.control.dev_episodes = 4;
        c.control.max_in_flight_per_team = 2;
    })
    .await;
    register_team(&f, "alpha", 4).await;
    register_team(&f, "bravo", 4).await;
    let jobs = f.lease("w", 64).await;
    assert_eq!(jobs.len(), 4, "two per team");
    let runs: BTreeSet<i64> = jobs.iter().map(|j| j.run_id).collect();
    assert_eq!(runs.len(), 2);
    for run in runs {
        assert_eq!(jobs.iter().filter(|j| j.run_id == run).count(), 2);
    }
    assert!(f.lease("w", 64).await.is_empty(), "both teams are at their cap");
    let r = f.report("w", &jobs[0], |_| true, 0.0);
    assert!(f.state.report_result(f.worker().await, r).await.unwrap().accepted);
    let more = f.lease("w", 64).await;
    assert_eq!(more.len(), 1);
    assert_eq!(more[0].run_id, jobs[0].run_id, "the freed place is that team's");
}

#[tokio::test]
async fn a_released_job_is_queued_at_once_without_using_an_attempt() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.max_attempts = 1;
        c.control.dev_episodes = 1;
        c.control.offline_mse = false;
    })
    .await;
    let (token, id) = registered(&f).await;
    let first = f.lease("w1", 1).await.remove(0);
    let release = async |worker: &str, attempt: u32| {
        (f.state)
            .release(f.worker().await, worker, first.id, attempt, "worker draining")
            .await
            .unwrap()
    };
    assert!(!release("w2", first.attempt).await, "only the holder may release");
    assert!(!release("w1", first.attempt + 1).await, "nor a stale attempt");
    // A long poll waiting for work wakes up when the job comes back.
    let (state, cred) = (f.state.clone(), f.worker().await);
    let waiter = tokio::spawn(async move { state.lease(cred, "w2", 1, 10_000).await.unwrap() });
    tokio::time::sleep(Duration::from_millis(50)).await;
    let t = std::time::Instant::now();
    assert!(release("w1", first.attempt).await);
    assert!(!release("w1", first.attempt).await, "released once");
    let again = waiter.await.unwrap().remove(0);
    assert!(t.elapsed() < Duration::from_secs(2), "{:?}", t.elapsed());
    assert_eq!((again.id, again.attempt), (first.id, 2));
    // The releasing worker's lease is gone: heartbeat cancelled, a late report refused.
    let hb = (f.state.heartbeat(f.worker().await, "w1", first.id, first.attempt))
        .await
        .unwrap();
    assert_eq!(hb.lease_expires_at_ms, None);
    let late = (f.state)
        .report_result(f.worker().await, f.report("w1", &first, |_| true, 0.0))
        .await
        .unwrap();
    assert!(!late.accepted);
    // max_attempts = 1 and the release used none: a platform error now is the one attempt.
    let mut r = f.report("w2", &again, |_| true, 0.0);
    r.platform_error = "simulator crashed".into();
    assert!(f.state.report_result(f.worker().await, r).await.unwrap().accepted);
    let eval = run_state(&f, &token, id).await;
    assert_eq!(eval.state, "platform_failed");
    let failure = eval.episodes[0].failure.clone().unwrap();
    assert!(failure.contains("gave up after 2 attempts"), "{failure}");
}

/// Polling a test run's view while it runs must not give each episode's failure kinds by
/// subtraction, so it shows progress only; the aggregate appears once it has ended
/// (docs/reference/pages.md: test split, the aggregate view only).
#[tokio::test]
async fn a_test_run_in_progress_shows_progress_only_and_its_failure_counts_once_ended() {
    let f = fixture(FakeProbe::ok(4), |_| {}).await;
    let token = f.team("alpha").await;
    let id = f
        .state
        .register_policy(&f.caller(&token).await, f.request(Split::Test))
        .await
        .unwrap()
        .id;
    let job = f.lease("w1", 1).await.remove(0);
    let failed = f.report("w1", &job, |_| false, 0.0);
    f.state.report_result(f.worker().await, failed).await.unwrap();
    let view = f.state.get_submission(&f.caller(&token).await, id).await.unwrap();
    let run = view.latest_run.unwrap();
    let eval = run.evaluation.unwrap();
    assert_eq!((eval.state, eval.episodes_done), ("running", 1));
    assert!(eval.episodes_total > 1);
    assert!(
        eval.failure_counts.is_empty(),
        "a running test run shows failure counts: {:?}",
        eval.failure_counts
    );
    assert!(eval.episodes.is_empty());
    assert_eq!(run.scores, crate::service::Scores::default());
    assert!(eval.eta.is_some(), "progress says when the run should end");

    // Once the run has ended (here: cancelled by the organiser), the aggregate is shown.
    f.state.cancel_run(f.admin().await, run.id).await.unwrap();
    let eval = run_state(&f, &token, id).await;
    assert_eq!(eval.state, "cancelled");
    assert!(eval.eta.is_none());
    assert_eq!(eval.failure_counts.len(), 1, "{:?}", eval.failure_counts);
    assert_eq!(eval.failure_counts[0].reason, "timeout");
}
