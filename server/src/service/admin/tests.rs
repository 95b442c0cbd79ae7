use kitchen_r_core::dataset::Split;

use super::*;
use crate::store::board;
use crate::testutil::{FakeProbe, Fixture, fixture};

async fn registered(f: &Fixture, team: &str) -> (String, i64, i64) {
    let token = f.team(team).await;
    let done = f
        .state
        .register_policy(&f.caller(&token).await, f.request(Split::Dev))
        .await
        .unwrap();
    let run: i64 = sqlx::query_scalar("SELECT MAX(id) FROM scoring_runs WHERE submission_id = ?")
        .bind(done.id)
        .fetch_one(f.state.pool())
        .await
        .unwrap();
    (token, done.id, run)
}

async fn eval_state(f: &Fixture, token: &str, id: i64) -> crate::service::PolicyRunView {
    let view = f.state.get_submission(&f.caller(token).await, id).await.unwrap();
    view.latest_run.unwrap().evaluation.unwrap()
}

#[tokio::test]
async fn cancel_stops_leasing_revokes_leases_ignores_late_reports_and_gives_the_quota_back() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.quota.dev_per_day = 1;
        c.quota.per_minute = 0;
    })
    .await;
    let (token, sub, run) = registered(&f, "alpha").await;
    let team = f.caller(&token).await;
    // The quota is used up.
    let refused = f.state.register_policy(&team, f.request(Split::Dev)).await;
    assert_eq!(refused.unwrap_err().code(), "quota_exceeded");

    let held = f.lease("w1", 1).await.remove(0);
    let total = eval_state(&f, &token, sub).await.episodes_total;
    let admin = f.admin().await;
    let done = f.state.cancel_run(admin, run).await.unwrap();
    assert_eq!(done.jobs_cancelled, total as u64);
    assert_eq!(done.leases_revoked, 1);
    assert_eq!(done.cancelled_by, "organiser");

    // Nothing of it is leased any more; the holder learns at its next heartbeat.
    assert!(f.lease("w2", 64).await.is_empty());
    let hb = f
        .state
        .heartbeat(f.worker().await, "w1", held.id, held.attempt)
        .await
        .unwrap();
    assert_eq!(hb.lease_expires_at_ms, None);
    // Its late report is not counted.
    let late = f
        .state
        .report_result(f.worker().await, f.report("w1", &held, |_| true, 0.0))
        .await
        .unwrap();
    assert!(!late.accepted);
    let eval = eval_state(&f, &token, sub).await;
    assert_eq!((eval.state, eval.episodes_done), ("cancelled", 0));

    // Marked with who and when.
    let (state, at, by): (String, Option<i64>, Option<String>) =
        sqlx::query_as("SELECT state, cancelled_at, cancelled_by FROM scoring_runs WHERE id = ?")
            .bind(run)
            .fetch_one(f.state.pool())
            .await
            .unwrap();
    assert_eq!((state.as_str(), by.as_deref()), ("cancelled", Some("organiser")));
    assert!(at.is_some());

    // The leaderboard entry was refreshed in the same transaction.
    let rows = board::read(f.state.read_pool(), board::CONTROL, Split::Dev)
        .await
        .unwrap();
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0].state, Some(RunState::Cancelled));
    assert_eq!(rows[0].sr, None);

    // The quota is back.
    f.state
        .register_policy(&team, f.request(Split::Dev))
        .await
        .expect("a cancelled run uses no quota");

    // Only an active run can be cancelled; an unknown one is not found.
    let again = f.state.cancel_run(admin, run).await.unwrap_err();
    assert_eq!(again.code(), "conflict", "{again}");
    assert_eq!(
        f.state.cancel_run(admin, 9999).await.unwrap_err().code(),
        "not_found"
    );
    // A cancelled run cannot be requeued.
    assert_eq!(
        f.state.requeue_run(admin, run).await.unwrap_err().code(),
        "conflict"
    );

    let runs = f.state.admin_runs(admin).await.unwrap();
    let ours = runs.runs.iter().find(|r| r.run == run).unwrap();
    assert_eq!(ours.state, RunState::Cancelled);
    assert_eq!(ours.cancelled_by.as_deref(), Some("organiser"));
}

#[tokio::test]
async fn requeue_puts_failed_and_stuck_jobs_back_with_their_attempts_and_the_run_finishes() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.max_attempts = 1;
        c.control.dev_episodes = 1;
    })
    .await;
    let (token, sub, run) = registered(&f, "alpha").await;
    let jobs = f.lease("w1", 64).await;
    assert!(jobs.len() >= 2, "an online and an offline episode");
    // The first fails on the platform (its only attempt), the others succeed.
    let mut r = f.report("w1", &jobs[0], |_| true, 0.0);
    r.platform_error = "simulator crashed".into();
    f.state.report_result(f.worker().await, r).await.unwrap();
    for j in &jobs[1..] {
        let r = f.report("w1", j, |_| true, 0.0);
        assert!(f.state.report_result(f.worker().await, r).await.unwrap().accepted);
    }
    let eval = eval_state(&f, &token, sub).await;
    assert_eq!(eval.state, "finished");
    let admin = f.admin().await;
    let queue = f.state.admin_queue(admin).await.unwrap();
    assert_eq!(queue.failed.len(), 1);
    assert!(
        queue.failed[0]
            .reason
            .as_deref()
            .unwrap()
            .contains("simulator crashed"),
        "{:?}",
        queue.failed[0]
    );

    let done = f.state.requeue_run(admin, run).await.unwrap();
    assert_eq!((done.jobs_requeued, done.stuck), (1, 0));
    assert_eq!(eval_state(&f, &token, sub).await.state, "running");
    let again = f.lease("w2", 64).await;
    assert_eq!(again.len(), 1);
    assert_eq!(again[0].id, jobs[0].id);
    assert_eq!(again[0].attempt, 2, "the lease counter keeps counting");

    // Stuck: leased past expiry (the worker went away); requeue takes it back at once.
    sqlx::query("UPDATE jobs SET lease_expires_at = 1 WHERE id = ?")
        .bind(again[0].id)
        .execute(f.state.pool())
        .await
        .unwrap();
    let queue = f.state.admin_queue(admin).await.unwrap();
    assert_eq!(queue.stuck.len(), 1);
    let done = f.state.requeue_run(admin, run).await.unwrap();
    assert_eq!((done.jobs_requeued, done.stuck), (1, 1));
    let third = f.lease("w3", 64).await.remove(0);
    assert_eq!(third.attempt, 3);
    let r = f.report("w3", &third, |_| true, 0.0);
    assert!(f.state.report_result(f.worker().await, r).await.unwrap().accepted);
    let eval = eval_state(&f, &token, sub).await;
    assert_eq!(eval.state, "finished");
    assert_eq!(eval.episodes_done, jobs.len() as i64);
    assert!(
        eval.episodes.iter().all(|e| e.failure.is_none()),
        "{:?}",
        eval.episodes
    );
    let rows = board::read(f.state.read_pool(), board::CONTROL, Split::Dev)
        .await
        .unwrap();
    assert_eq!(rows[0].state, Some(RunState::Finished));
    assert!(rows[0].sr.is_some());
    assert_eq!(
        f.state.requeue_run(admin, 4242).await.unwrap_err().code(),
        "not_found"
    );
}

#[tokio::test]
async fn the_console_shows_queue_workers_runs_and_each_teams_share() {
    let f = fixture(FakeProbe::ok(8), |c| c.quota.per_minute = 0).await;
    let (_, _, run_a) = registered(&f, "alpha").await;
    let (_, _, run_b) = registered(&f, "bravo").await;
    let w1 = "<i>w1</i>";
    let held = f.lease(w1, 2).await;
    assert_eq!(held.len(), 2);
    let r = f.report(w1, &held[0], |_| true, 0.0);
    f.state.report_result(f.worker().await, r).await.unwrap();
    let admin = f.admin().await;

    let queue = f.state.admin_queue(admin).await.unwrap();
    assert_eq!(queue.jobs["leased"], 1);
    assert_eq!(queue.jobs["done"], 1);
    assert!(queue.jobs["queued"] > 0 && queue.oldest_queued_age_s.is_some());
    // One episode in flight: its team has all of the share.
    let busy = if held[1].run_id == run_a { "alpha" } else { "bravo" };
    let share = queue.teams.iter().find(|t| t.team == busy).unwrap();
    assert_eq!((share.in_flight, share.share), (1, 1.0));
    assert_eq!(queue.teams.iter().map(|t| t.in_flight).sum::<i64>(), 1);
    assert!(queue.teams.iter().any(|t| t.team == "bravo" && t.queued > 0));

    let workers = f.state.admin_workers(admin).await.unwrap();
    assert_eq!(workers.workers.len(), 1);
    let w = &workers.workers[0];
    assert_eq!((w.worker.as_str(), w.episodes_24h), (w1, 1));
    assert_eq!(w.current.len(), 1);
    assert_eq!(w.current[0].episode, held[1].episode_key);
    assert!(w.last_heartbeat.is_some());

    let runs = f.state.admin_runs(admin).await.unwrap();
    assert_eq!(runs.runs.len(), 2);
    let reported = runs.runs.iter().find(|r| r.run == held[0].run_id).unwrap();
    assert_eq!(reported.episodes_done, 1);
    assert!(reported.eta.is_some() && reported.mean_episode_s.is_some());
    let running: i64 = runs.runs.iter().map(|r| r.episodes_running).sum();
    assert_eq!(running, 1);
    assert!(
        runs.runs
            .iter()
            .any(|r| [run_a, run_b].contains(&r.run) && r.episodes_done == 0 && r.eta.is_none())
    );

    // The page built from these (and that it escapes them) is the HTTP adapter's:
    // `http/admin/tests.rs`, `the_console_page_escapes_what_others_wrote`.
}

#[tokio::test]
async fn a_backup_is_a_consistent_copy_and_leaves_nothing_behind() {
    let f = fixture(FakeProbe::ok(8), |_| {}).await;
    registered(&f, "alpha").await;
    let dir = std::path::Path::new(f.state.config().db.trim_start_matches("sqlite://"))
        .parent()
        .unwrap()
        .to_path_buf();
    let before: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    let mut b = f.state.backup(f.admin().await).await.unwrap();
    let after: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(before, after, "the copy is unlinked at once");
    let mut bytes = Vec::new();
    tokio::io::AsyncReadExt::read_to_end(&mut b.file, &mut bytes)
        .await
        .unwrap();
    assert_eq!(bytes.len() as u64, b.len);
    assert!(bytes.starts_with(b"SQLite format 3\0"));
    let copy = dir.join("copy.db");
    std::fs::write(&copy, &bytes).unwrap();
    let pool = sqlx::sqlite::SqlitePoolOptions::new()
        .connect(&format!("sqlite://{}", copy.display()))
        .await
        .unwrap();
    let n: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM jobs")
        .fetch_one(&pool)
        .await
        .unwrap();
    assert!(n > 0);
    let ok: String = sqlx::query_scalar("PRAGMA integrity_check")
        .fetch_one(&pool)
        .await
        .unwrap();
    assert_eq!(ok, "ok");
}
