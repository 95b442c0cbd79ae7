//! Videos rendered on demand (docs/contest/video.md) from stored traces: a render never leases
//! while an evaluation job waits, a lost render lease is queued again, a failed render says why,
//! and a render of a trace rendered before reuses its video.

use super::*;
use crate::service::WorkerCred;
use crate::service::renders::VideoState;

async fn render_fixture() -> Fixture {
    fixture(FakeProbe::ok(8), |c| {
        c.control.offline_mse = false;
        c.control.dev_episodes = 2;
        c.control.lease_s = 30;
        c.quota.concurrent_runs = 0;
    })
    .await
}

/// Store `bytes` as the trace of `(run, key)`, as an upload does.
async fn store_trace(f: &Fixture, run: i64, key: &str, bytes: &[u8]) {
    let dir = f.state.video_dir().unwrap();
    let mut up = Incoming::start(&dir, bytes.len() as u64, 1 << 20).await.unwrap();
    up.write(bytes).await.unwrap();
    let done = up.finish().await.unwrap();
    let booking = (f.state.book_trace(&dir, run, key, bytes.len() as u64).await).unwrap();
    f.state.store_trace(&dir, booking, run, key, done).await.unwrap();
}

/// Team alpha's dev policy run, registered, and a worker's credentials.
struct DevRun {
    token: String,
    caller: Caller,
    id: i64,
    worker: WorkerCred,
}

async fn dev_run(f: &Fixture) -> DevRun {
    let token = f.team("alpha").await;
    let caller = f.caller(&token).await;
    let id = (f.state.register_policy(&caller, f.request(Split::Dev)).await)
        .unwrap()
        .id;
    let worker = f.worker().await;
    DevRun {
        token,
        caller,
        id,
        worker,
    }
}

#[tokio::test]
async fn a_render_waits_for_evaluation_and_a_lost_render_lease_is_queued_again() {
    let f = render_fixture().await;
    let DevRun {
        caller, id, worker, ..
    } = dev_run(&f).await;
    // One of the two episodes is evaluated and reported; the other stays queued.
    let job = f.lease("w1", 1).await.remove(0);
    let report = f.report("w1", &job, |_| false, 0.0);
    f.state.report_result(worker, report).await.unwrap();
    store_trace(&f, job.run_id, &job.episode_key, b"\x1f\x8b trace").await;

    let key = job.episode_key.as_str();
    let state = f.state.video_or_render(&caller, id, key).await.unwrap();
    assert!(
        matches!(state, VideoState::Rendering { leased: false, .. }),
        "{state:?}"
    );
    // An evaluation job waits: the worker gets it, and no render.
    let (jobs, render) = (f.state).lease_work(worker, "w1", 4, 0, true).await.unwrap();
    assert_eq!(jobs.len(), 1);
    assert!(render.is_none(), "a render leased while an evaluation job waited");
    // Nothing else queued: the render goes out, with the trace and the stored result.
    let (jobs, render) = (f.state).lease_work(worker, "w2", 4, 0, true).await.unwrap();
    let render = render.expect("the render is leased once no evaluation job waits");
    assert!(jobs.is_empty());
    assert_eq!((render.run_id, render.episode_key.as_str()), (job.run_id, key));
    // The trace is named, not carried: the worker fetches it in chunks.
    assert_eq!(render.trace_bytes, 8);
    assert_eq!(
        render.trace_sha256,
        hex::encode(Sha256::digest(b"\x1f\x8b trace"))
    );
    assert_eq!(render.expected.len(), job.spec.task_count());
    assert!(render.expected.iter().all(|t| !t.success));
    // Its progress is what the episode shows.
    let hb = (f.state)
        .render_heartbeat(worker, "w2", render.id, render.attempt, 0.5)
        .await
        .unwrap();
    assert!(hb.lease_expires_at_ms.is_some());
    let state = f.state.video_or_render(&caller, id, key).await.unwrap();
    assert!(
        matches!(state, VideoState::Rendering { leased: true, progress } if progress == 0.5),
        "{state:?}"
    );
    // The worker dies: its lease expires and the render is queued again, for anyone.
    let later = now_ms() + 31_000;
    assert_eq!(f.state.reap_renders(later).await.unwrap(), 1);
    let again = f.state.claim_render("w3").await.unwrap().unwrap();
    assert_eq!((again.id, again.attempt), (render.id, render.attempt + 1));
    // The stale lease can neither heartbeat nor fail it.
    let stale = (f.state)
        .render_heartbeat(worker, "w2", render.id, render.attempt, 0.9)
        .await
        .unwrap();
    assert!(stale.lease_expires_at_ms.is_none());
    assert!(
        !(f.state)
            .fail_render(worker, "w2", render.id, render.attempt, "late")
            .await
            .unwrap()
    );
    // The holder reports the replay refused: the episode says why, and is not tried again.
    let why = "replay disagrees with the stored result: task 0: replayed failure, stored success";
    assert!(
        (f.state)
            .fail_render(worker, "w3", again.id, again.attempt, why)
            .await
            .unwrap()
    );
    match f.state.video_or_render(&caller, id, key).await.unwrap() {
        VideoState::Failed(e) => assert_eq!(e, why),
        other => panic!("{other:?}"),
    }
    assert!(f.state.claim_render("w3").await.unwrap().is_none());
    let view = f.state.get_submission(&caller, id).await.unwrap();
    let eps = view.latest_run.unwrap().evaluation.unwrap().episodes;
    let shown = eps.iter().find(|e| e.key == key).unwrap();
    assert_eq!(shown.video.as_ref().unwrap().status, "failed");
    assert!(shown.video_note.as_deref().unwrap().contains(why));
    // Another team never learns of it.
    let other = f.caller(&f.team("bravo").await).await;
    assert!(f.state.video_or_render(&other, id, key).await.is_err());
    assert!(f.state.episode_trace(&other, id, key).await.is_err());
}

#[tokio::test]
async fn a_second_episode_with_the_same_trace_reuses_the_rendered_video() {
    let f = render_fixture().await;
    let DevRun {
        token,
        caller,
        id,
        worker,
    } = dev_run(&f).await;
    let jobs = f.lease("w1", 4).await;
    for job in &jobs {
        let report = f.report("w1", job, |_| false, 0.0);
        f.state.report_result(worker, report).await.unwrap();
        // A deterministic policy: the same trace (in this test) for both episodes.
        store_trace(&f, job.run_id, &job.episode_key, b"same trace").await;
    }
    let (a, b) = (&jobs[0].episode_key, &jobs[1].episode_key);
    f.state.video_or_render(&caller, id, a).await.unwrap();
    let render = f.state.claim_render("w1").await.unwrap().unwrap();
    // The render's video upload, as `grpc_worker::upload` stores it.
    let dir = f.state.video_dir().unwrap();
    let sha = store_file(&dir, b"rendered mp4").await;
    crate::store::videos::link(
        f.state.pool(),
        crate::store::videos::Row {
            run: render.run_id,
            key: a,
            team: f.team_of(&token).await.id,
            now: now_ms(),
        },
        &sha,
        12,
    )
    .await
    .unwrap();
    crate::store::renders::done(
        f.state.pool(),
        render.id,
        i64::from(render.attempt),
        &sha,
        now_ms(),
    )
    .await
    .unwrap();
    // The other episode's video is the same file, at once, with no render queued.
    match f.state.video_or_render(&caller, id, b).await.unwrap() {
        VideoState::Ready(v) => assert_eq!(v.sha256, sha),
        other => panic!("{other:?}"),
    }
    assert!(f.state.claim_render("w1").await.unwrap().is_none());
}

#[tokio::test]
async fn a_failed_episodes_video_is_prerendered_behind_every_asked_for_render() {
    let f = render_fixture().await;
    let DevRun {
        caller, id, worker, ..
    } = dev_run(&f).await;
    let dir = f.state.video_dir().unwrap();
    let jobs = f.lease("w1", 4).await;
    let (failed, passed) = (&jobs[0], &jobs[1]);
    for (job, success, trace) in [
        (failed, false, &b"failed trace"[..]),
        (passed, true, b"passed trace"),
    ] {
        let report = f.report("w1", job, |_| success, 0.0);
        f.state.report_result(worker, report).await.unwrap();
        store_trace(&f, job.run_id, &job.episode_key, trace).await;
        // What the trace upload does once the trace is stored (`[video] prerender = "failed"`).
        f.state
            .prerender(&dir, job.run_id, &job.episode_key)
            .await
            .unwrap();
    }
    // Only the failed episode's render is queued, and nobody asked for it yet.
    let rows = crate::store::renders::of_run(f.state.read_pool(), failed.run_id)
        .await
        .unwrap();
    assert_eq!(rows.len(), 1, "{rows:?}");
    assert_eq!(rows[0].episode_key, failed.episode_key);
    // Someone asks for the passed episode's video: its render goes first.
    f.state
        .video_or_render(&caller, id, &passed.episode_key)
        .await
        .unwrap();
    let first = f.state.claim_render("w1").await.unwrap().unwrap();
    assert_eq!(
        first.episode_key, passed.episode_key,
        "the asked-for render first"
    );
    let second = f.state.claim_render("w2").await.unwrap().unwrap();
    assert_eq!(second.episode_key, failed.episode_key, "then the pre-render");
    // Storing the same trace again queues nothing new: the render exists.
    f.state
        .prerender(&dir, failed.run_id, &failed.episode_key)
        .await
        .unwrap();
    assert!(f.state.claim_render("w3").await.unwrap().is_none());
}

#[tokio::test]
async fn asking_for_a_queued_prerender_moves_it_ahead_and_none_prerenders_nothing() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.offline_mse = false;
        c.control.dev_episodes = 3;
        c.quota.concurrent_runs = 0;
        c.video.prerender = crate::config::Prerender::All;
    })
    .await;
    let DevRun {
        caller, id, worker, ..
    } = dev_run(&f).await;
    let dir = f.state.video_dir().unwrap();
    let jobs = f.lease("w1", 4).await;
    for (i, job) in jobs.iter().enumerate() {
        let report = f.report("w1", job, |_| true, 0.0);
        f.state.report_result(worker, report).await.unwrap();
        store_trace(&f, job.run_id, &job.episode_key, format!("trace {i}").as_bytes()).await;
        f.state
            .prerender(&dir, job.run_id, &job.episode_key)
            .await
            .unwrap();
    }
    // `all`: every episode is pre-rendered, oldest first; asking for the last moves it ahead.
    let last = &jobs[2].episode_key;
    match f.state.video_or_render(&caller, id, last).await.unwrap() {
        VideoState::Rendering { leased: false, .. } => {}
        other => panic!("{other:?}"),
    }
    let first = f.state.claim_render("w1").await.unwrap().unwrap();
    assert_eq!(&first.episode_key, last);
    assert_eq!(
        f.state.claim_render("w1").await.unwrap().unwrap().episode_key,
        jobs[0].episode_key
    );

    let none = fixture(FakeProbe::ok(8), |c| {
        c.control.offline_mse = false;
        c.control.dev_episodes = 1;
        c.quota.concurrent_runs = 0;
        c.video.prerender = crate::config::Prerender::None;
    })
    .await;
    let caller = none.caller(&none.team("alpha").await).await;
    none.state
        .register_policy(&caller, none.request(Split::Dev))
        .await
        .unwrap();
    let worker = none.worker().await;
    let job = none.lease("w1", 1).await.remove(0);
    let report = none.report("w1", &job, |_| false, 0.0);
    none.state.report_result(worker, report).await.unwrap();
    store_trace(&none, job.run_id, &job.episode_key, b"trace").await;
    let dir = none.state.video_dir().unwrap();
    none.state
        .prerender(&dir, job.run_id, &job.episode_key)
        .await
        .unwrap();
    assert!(
        none.state.claim_render("w1").await.unwrap().is_none(),
        "none: only on request"
    );
}

/// A render whose every lease was lost fails saying whose lease it was last and how far it got, not
/// only that "no worker finished it".
#[tokio::test]
async fn a_render_out_of_attempts_says_whose_lease_ended_and_how_far_it_got() {
    let f = render_fixture().await;
    let DevRun {
        caller, id, worker, ..
    } = dev_run(&f).await;
    let job = f.lease("w1", 2).await.remove(0);
    let report = f.report("w1", &job, |_| false, 0.0);
    f.state.report_result(worker, report).await.unwrap();
    for j in f.lease("w1", 2).await {
        let report = f.report("w1", &j, |_| false, 0.0);
        f.state.report_result(worker, report).await.unwrap();
    }
    store_trace(&f, job.run_id, &job.episode_key, b"trace").await;
    let key = job.episode_key.as_str();
    f.state.video_or_render(&caller, id, key).await.unwrap();
    let render = f.state.claim_render("w7").await.unwrap().unwrap();
    let hb = (f.state)
        .render_heartbeat(worker, "w7", render.id, render.attempt, 0.25)
        .await
        .unwrap();
    let expired = hb.lease_expires_at_ms.unwrap() + 1;
    store::renders::reap(f.state.pool(), expired, i64::from(render.attempt))
        .await
        .unwrap();
    let failed = store::renders::render(f.state.pool(), job.run_id, key)
        .await
        .unwrap()
        .unwrap();
    assert_eq!(failed.state, "failed");
    let why = failed.error.unwrap();
    assert!(
        why.contains("tried 1 time and") && why.contains("w7, stopped at 25 %"),
        "{why}"
    );
}
