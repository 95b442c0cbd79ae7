//! Storage budgets (docs/contest/video.md): traces count in the storage budgets beside videos, a
//! team within its fair share of the total never loses a file to another team's upload (sequential
//! and in parallel), the traces of a ranked test run are never removed, and a render whose video
//! finds no room waits, queued, saying why.

use super::budget::{KIB, budget_fixture, dev_run, note_of, shown};
use super::*;

/// The trace upload stream of `data` for `job`, in one chunk.
fn trace_upload(
    job: &(i64, i64, i64, String),
    data: &[u8],
) -> Request<tokio_stream::Iter<std::vec::IntoIter<pb::TraceChunk>>> {
    let chunk = pb::TraceChunk {
        worker_id: "w1".into(),
        job_id: job.0,
        attempt: job.1 as u32,
        run_id: job.2,
        episode_key: job.3.clone(),
        total_bytes: data.len() as u64,
        data: data.to_vec(),
    };
    let mut req = Request::new(tokio_stream::iter(vec![chunk]));
    req.metadata_mut()
        .insert("authorization", format!("Bearer {WORKER}").parse().unwrap());
    req
}

/// Stored bytes per team name, videos and traces together.
async fn usage(f: &Fixture) -> Vec<(String, i64)> {
    sqlx::query_as(
        "SELECT t.name, SUM(u.bytes) FROM (
             SELECT team_id, bytes FROM episode_videos WHERE note IS NULL
             UNION ALL SELECT team_id, bytes FROM episode_traces WHERE note IS NULL) u
         JOIN teams t ON t.id = u.team_id GROUP BY t.name ORDER BY t.name",
    )
    .fetch_all(f.state.pool())
    .await
    .unwrap()
}

/// The review's case: a team with one small video, far under its budget, lost it to two other
/// teams' uploads. Now only teams over their fair share give way.
#[tokio::test]
async fn a_team_within_its_fair_share_keeps_its_files_while_others_fill_the_total() {
    let f = budget_fixture().await;
    let (charlie, charlie_id, c) = dev_run(&f, "charlie").await;
    let (_, _, a) = dev_run(&f, "alpha").await;
    let (bravo, bravo_id, b) = dev_run(&f, "bravo").await;
    let mut client = f.worker_client().await;
    client.upload_video(upload(&c[0], &[1; 500], 500)).await.unwrap();
    for (job, n) in a.iter().zip(10..) {
        client
            .upload_video(upload(job, &vec![n; 1000], 1000))
            .await
            .unwrap();
    }
    // bravo fills the 3 KiB total with its own uploads: alpha (over its share, 1 KiB of three
    // teams) gives way, then bravo itself; charlie's 500 bytes stay.
    for (job, n) in b.iter().zip(20..) {
        client
            .upload_video(upload(job, &vec![n; 1000], 1000))
            .await
            .unwrap();
    }
    assert_eq!(
        note_of(&shown(&f, &charlie, charlie_id).await, &c[0].3),
        (true, None)
    );
    let eps = shown(&f, &bravo, bravo_id).await;
    let (url, note) = note_of(&eps, &b[0].3);
    assert!(!url, "{eps:?}");
    assert!(note.unwrap().contains("fair share"), "{note:?}");
    let total: i64 = usage(&f).await.iter().map(|u| u.1).sum();
    assert!(total as u64 <= 3 * KIB, "{:?}", usage(&f).await);
}

/// Traces are booked like videos: past its budget a team's videos go first (they can be
/// rendered again from their traces), then its oldest traces, whose episodes say the video
/// cannot come back.
#[tokio::test]
async fn traces_count_in_the_budgets_and_outlast_the_videos_rendered_from_them() {
    // Nothing pre-rendered: the videos here are uploaded by hand.
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.offline_mse = false;
        c.quota.concurrent_runs = 0;
        c.video.max_bytes = KIB;
        c.video.team_max_bytes = 2 * KIB;
        c.video.total_max_bytes = 3 * KIB;
        c.video.prerender = crate::config::Prerender::None;
    })
    .await;
    let (alpha, alpha_id, a) = dev_run(&f, "alpha").await;
    let mut client = f.worker_client().await;
    client.upload_trace(trace_upload(&a[0], &[1; 700])).await.unwrap();
    client.upload_video(upload(&a[0], &[2; 700], 700)).await.unwrap();
    client.upload_trace(trace_upload(&a[1], &[3; 700])).await.unwrap();
    // 2100 bytes would pass alpha's 2 KiB: its video goes, both traces stay.
    let eps = shown(&f, &alpha, alpha_id).await;
    let (_, note) = note_of(&eps, &a[0].3);
    assert!(note.is_some_and(|n| n.contains("rendered again")), "{eps:?}");
    assert_eq!(usage(&f).await, vec![("alpha".into(), 1400)]);
    // Two more traces: the oldest trace goes (no video left to go first).
    client.upload_trace(trace_upload(&a[2], &[4; 700])).await.unwrap();
    client.upload_video(upload(&a[1], &[5; 600], 600)).await.unwrap();
    let eps = shown(&f, &alpha, alpha_id).await;
    let (url, note) = note_of(&eps, &a[0].3);
    assert!(!url, "{eps:?}");
    assert!(note.unwrap().contains("can no longer be rendered"), "{eps:?}");
    assert!(usage(&f).await[0].1 as u64 <= 2 * KIB);
}

/// Many teams uploading at once: every budget holds after every upload, and a team within its
/// share keeps its file.
#[tokio::test]
async fn budgets_hold_across_teams_uploading_in_parallel() {
    let f = budget_fixture().await;
    let (small, small_id, s) = dev_run(&f, "small").await;
    let mut client = f.worker_client().await;
    client.upload_trace(trace_upload(&s[0], &[9; 300])).await.unwrap();
    let mut runs = Vec::new();
    for name in ["alpha", "bravo", "charlie"] {
        runs.push(dev_run(&f, name).await.2);
    }
    let mut tasks = tokio::task::JoinSet::new();
    for (t, jobs) in runs.into_iter().enumerate() {
        let mut client = f.worker_client().await;
        tasks.spawn(async move {
            for (i, job) in jobs.iter().enumerate() {
                let data = vec![(t * 10 + i) as u8; 900];
                // In flight together, an upload may find the rest booked: it is tried again.
                for _ in 0..20 {
                    match client.upload_trace(trace_upload(job, &data)).await {
                        Ok(_) => break,
                        Err(e) if e.code() == Code::ResourceExhausted => tokio::task::yield_now().await,
                        Err(e) => panic!("{e:?}"),
                    }
                }
            }
        });
    }
    while let Some(r) = tasks.join_next().await {
        r.unwrap();
    }
    let used = usage(&f).await;
    let total: i64 = used.iter().map(|u| u.1).sum();
    assert!(total as u64 <= 3 * KIB, "{used:?}");
    assert!(used.iter().all(|u| u.1 as u64 <= 2 * KIB), "{used:?}");
    assert!(used.contains(&("small".into(), 300)), "{used:?}");
    let keys = store::traces::keys(f.state.pool(), s[0].2).await.unwrap();
    assert_eq!(keys, vec![s[0].3.clone()], "small's trace was removed");
    let _ = (small, small_id);
}

/// The traces of a ranked test run are never removed, by a budget or by retention; a video with
/// no room then waits, queued, and its episode says why.
#[tokio::test]
async fn ranked_test_traces_are_kept_and_a_render_with_no_room_waits_saying_why() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.dev_episodes = 1;
        c.video.max_bytes = KIB;
        c.video.team_max_bytes = 2 * KIB;
        c.video.total_max_bytes = 2 * KIB;
        c.video.retention_days = 1;
        c.video.prerender = crate::config::Prerender::None;
    })
    .await;
    let (alpha, _, dev, test) = f.runs_with_paths(|_| Default::default()).await;
    let jobs = done_jobs(&f).await;
    let test_run = store::latest_run(f.state.pool(), test).await.unwrap().unwrap().id;
    let test_jobs: Vec<_> = jobs.iter().filter(|j| j.2 == test_run).collect();
    let on_board: bool = sqlx::query_scalar(
        "SELECT EXISTS (SELECT 1 FROM leaderboard_entries WHERE submission_id = ? AND split = 'test')",
    )
    .bind(test)
    .fetch_one(f.state.pool())
    .await
    .unwrap();
    assert!(on_board, "the test run is not ranked");
    let mut client = f.worker_client().await;
    for (job, n) in test_jobs.iter().take(2).zip(1..) {
        client
            .upload_trace(trace_upload(job, &vec![n; 1000]))
            .await
            .unwrap();
    }
    // alpha's 2 KiB is all protected traces: a dev trace finds no room, and none was removed.
    let dev_job = jobs.iter().find(|j| j.2 != test_run).unwrap();
    let e = client
        .upload_trace(trace_upload(dev_job, &[7; 100]))
        .await
        .unwrap_err();
    assert_eq!(e.code(), Code::ResourceExhausted, "{e:?}");
    assert!(e.message().contains("ranked test runs"), "{e:?}");
    // Retention passes them by.
    f.state.sweep_videos(now_ms() + 3 * 86_400_000).await.unwrap();
    assert_eq!(
        store::traces::keys(f.state.pool(), test_run).await.unwrap().len(),
        2
    );

    // A render of one of them cannot store its video: it waits, queued, with the reason.
    let organiser = Caller::Organiser(f.admin().await);
    let key = &test_jobs[0].3;
    f.state.video_or_render(&organiser, test, key).await.unwrap();
    let worker = f.worker().await;
    let (_, render) = f.state.lease_work(worker, "w1", 4, 0, true).await.unwrap();
    let render = render.expect("the render is leased");
    let mut chunk = pb::VideoChunk {
        worker_id: "w1".into(),
        job_id: render.id,
        attempt: render.attempt,
        run_id: render.run_id,
        episode_key: render.episode_key.clone(),
        total_bytes: 500,
        data: vec![0; 500],
        render: true,
    };
    chunk.worker_id = "w1".into();
    let mut req = Request::new(tokio_stream::iter(vec![chunk]));
    req.metadata_mut()
        .insert("authorization", format!("Bearer {WORKER}").parse().unwrap());
    let e = client.upload_video(req).await.unwrap_err();
    assert_eq!(e.code(), Code::ResourceExhausted, "{e:?}");
    let views = f.state.video_views(test_run, |k| k.to_string()).await.unwrap();
    let v = &views[key.as_str()];
    assert_eq!(v.status, "queued", "{v:?}");
    assert!(
        v.waiting.as_deref().unwrap().contains("ranked test runs"),
        "{v:?}"
    );
    // Not leased again before its pause is over, and the wait was no attempt.
    let (_, again) = f.state.lease_work(worker, "w1", 4, 0, true).await.unwrap();
    assert!(again.is_none(), "a waiting render was leased at once");
    let attempt: i64 = sqlx::query_scalar("SELECT attempt FROM video_renders WHERE id = ?")
        .bind(render.id)
        .fetch_one(f.state.pool())
        .await
        .unwrap();
    assert_eq!(attempt, 0);
    let _ = (alpha, dev);
}
