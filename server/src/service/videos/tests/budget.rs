//! Issue 23: bounded video storage (per-team and total budgets, oldest evicted first, the
//! episode saying so) and no file left that nothing links.

use super::*;

/// Videos of one KiB at most, a team budget of two, four in all.
pub(super) const KIB: u64 = 1024;

pub(super) async fn budget_fixture() -> Fixture {
    fixture(FakeProbe::ok(8), |c| {
        c.control.offline_mse = false;
        c.quota.concurrent_runs = 0;
        c.video.max_bytes = KIB;
        c.video.team_max_bytes = 2 * KIB;
        c.video.total_max_bytes = 3 * KIB;
    })
    .await
}

/// `team` registers a dev policy run whose three episodes are all reported; returns the
/// submission id and the jobs.
pub(super) async fn dev_run(f: &Fixture, team: &str) -> (String, i64, Vec<(i64, i64, i64, String)>) {
    let token = f.team(team).await;
    let caller = f.caller(&token).await;
    let id = f
        .state
        .register_policy(&caller, f.request(Split::Dev))
        .await
        .unwrap()
        .id;
    let worker = f.worker().await;
    for job in f.lease("w1", 16).await {
        let report = f.report("w1", &job, |_| false, 0.0);
        f.state.report_result(worker, report).await.unwrap();
    }
    let run = store::latest_run(f.state.pool(), id).await.unwrap().unwrap().id;
    let jobs = done_jobs(f)
        .await
        .into_iter()
        .filter(|j| j.2 == run)
        .collect::<Vec<_>>();
    assert_eq!(jobs.len(), 3, "{jobs:?}");
    (token, id, jobs)
}

/// Each episode's `(key, video_url present, video_note)` as its team sees the submission.
pub(super) async fn shown(f: &Fixture, token: &str, id: i64) -> Vec<(String, bool, Option<String>)> {
    let view = f.state.get_submission(&f.caller(token).await, id).await.unwrap();
    let eps = view.latest_run.unwrap().evaluation.unwrap().episodes;
    eps.into_iter()
        .map(|e| (e.key, e.video_url.is_some(), e.video_note))
        .collect()
}

pub(super) fn note_of<'a>(eps: &'a [(String, bool, Option<String>)], key: &str) -> (bool, Option<&'a str>) {
    let e = eps.iter().find(|e| e.0 == key).unwrap();
    (e.1, e.2.as_deref())
}

#[tokio::test]
async fn uploads_past_a_budget_evict_the_oldest_videos_and_their_episodes_say_why() {
    let f = budget_fixture().await;
    let (alpha, alpha_id, a) = dev_run(&f, "alpha").await;
    let (bravo, bravo_id, b) = dev_run(&f, "bravo").await;
    let mut client = f.worker_client().await;
    let dir = f.state.video_dir().unwrap();
    let video = |n: u8| vec![n; 1000];
    let mut sha = Vec::new();
    for (job, n) in a.iter().zip(1..) {
        let v = video(n);
        let answer = client
            .upload_video(upload(job, &v, 1000))
            .await
            .unwrap()
            .into_inner();
        sha.push(answer.sha256);
    }
    // alpha's third video passed its 2 KiB: its first is gone, file and all; the others stay.
    let eps = shown(&f, &alpha, alpha_id).await;
    let (url, note) = note_of(&eps, &a[0].3);
    assert!(!url, "{eps:?}");
    let note = note.unwrap_or_else(|| panic!("no note on the evicted episode: {eps:?}"));
    assert!(
        note.contains("team alpha's videos and traces within [video] team_max_bytes (2 KiB)"),
        "{note}"
    );
    assert!(!file_path(&dir, &sha[0]).exists());
    assert_eq!(note_of(&eps, &a[1].3), (true, None));
    assert_eq!(note_of(&eps, &a[2].3), (true, None));
    let own = f.caller(&alpha).await;
    let gone = f.state.episode_video(&own, alpha_id, &a[0].3).await;
    assert!(matches!(gone, Err(ServiceError::NotFound { .. })), "{gone:?}");

    // bravo's first fits the 3 KiB total (3000 bytes); its second does not: the oldest video
    // of any team goes, alpha's second, and bravo's own stay.
    for (job, n) in b.iter().take(2).zip(11..) {
        client.upload_video(upload(job, &video(n), 1000)).await.unwrap();
    }
    let eps = shown(&f, &alpha, alpha_id).await;
    let (url, note) = note_of(&eps, &a[1].3);
    assert!(!url);
    assert!(
        note.unwrap().contains("[video] total_max_bytes (3 KiB)"),
        "{note:?}"
    );
    assert!(!file_path(&dir, &sha[1]).exists());
    assert_eq!(note_of(&eps, &a[2].3), (true, None), "the newest is kept");
    let eps = shown(&f, &bravo, bravo_id).await;
    assert!(eps.iter().filter(|e| e.1).count() == 2, "{eps:?}");
    // Stored: alpha's newest and bravo's two, one file each.
    let mp4s = files(&dir);
    assert_eq!(mp4s.len(), 3, "{mp4s:?}");
    assert_eq!(store::videos::stored_bytes(f.state.pool()).await.unwrap(), 3000);
}

#[tokio::test]
async fn an_upload_in_flight_holds_its_room_until_linked() {
    let f = budget_fixture().await;
    let (alpha, alpha_id, a) = dev_run(&f, "alpha").await;
    let dir = f.state.video_dir().unwrap();
    // Two uploads of alpha in flight (booked, not linked): the team's 2 KiB is taken.
    let first = f.state.book_video(&dir, a[0].2, &a[0].3, 1000).await.unwrap();
    let second = f.state.book_video(&dir, a[1].2, &a[1].3, 1000).await.unwrap();
    // A third cannot fit even by evicting everything stored: refused, and its episode says so.
    let third = f.state.book_video(&dir, a[2].2, &a[2].3, 1000).await;
    assert!(matches!(third, Err(UploadError::NoRoom(_))), "{:?}", third.err());
    let eps = shown(&f, &alpha, alpha_id).await;
    let (url, note) = note_of(&eps, &a[2].3);
    assert!(!url);
    assert!(note.unwrap().starts_with("video not stored"), "{note:?}");
    // Once one upload ends, its room is free again, and a retry stores the video.
    drop(second);
    let up = f.state.book_video(&dir, a[2].2, &a[2].3, 1000).await.unwrap();
    let mut file = Incoming::start(&dir, 3, KIB).await.unwrap();
    file.write(b"abc").await.unwrap();
    let done = file.finish().await.unwrap();
    f.state
        .store_video(&dir, up, a[2].2, &a[2].3, done)
        .await
        .unwrap();
    let eps = shown(&f, &alpha, alpha_id).await;
    assert_eq!(note_of(&eps, &a[2].3), (true, None), "{eps:?}");
    drop(first);
}

#[tokio::test]
async fn a_replaced_video_deletes_the_old_file_unless_another_episode_links_it() {
    let f = budget_fixture().await;
    let (_, _, a) = dev_run(&f, "alpha").await;
    let mut client = f.worker_client().await;
    let dir = f.state.video_dir().unwrap();
    let up = |job: &(i64, i64, i64, String), v: &[u8]| upload(job, v, v.len() as u64);
    let old = client
        .upload_video(up(&a[0], b"first take"))
        .await
        .unwrap()
        .into_inner();
    let new = client
        .upload_video(up(&a[0], b"second take"))
        .await
        .unwrap()
        .into_inner();
    assert!(
        !file_path(&dir, &old.sha256).exists(),
        "the replaced file is still on disk"
    );
    assert!(file_path(&dir, &new.sha256).exists());
    // The same bytes linked from two episodes: replacing one link keeps the file.
    client.upload_video(up(&a[1], b"second take")).await.unwrap();
    client.upload_video(up(&a[0], b"third take")).await.unwrap();
    assert!(
        file_path(&dir, &new.sha256).exists(),
        "a file another episode links was deleted"
    );
    assert_eq!(files(&dir).len(), 2, "{:?}", files(&dir));
}

#[tokio::test]
async fn a_start_removes_partial_uploads_and_files_no_episode_links() {
    let f = budget_fixture().await;
    let (_, _, a) = dev_run(&f, "alpha").await;
    let dir = f.state.video_dir().unwrap();
    let mut client = f.worker_client().await;
    let kept = client
        .upload_video(upload(&a[0], b"kept", 4))
        .await
        .unwrap()
        .into_inner();
    // What a killed process leaves: a partial upload, and a file placed but never linked.
    std::fs::create_dir_all(dir.join("tmp")).unwrap();
    std::fs::write(dir.join("tmp/123-456-0.part"), b"half a vid").unwrap();
    let stray = store_file(&dir, b"placed, never linked").await;
    // A trace placed but never linked goes too.
    let stray_trace = trace_path(&dir, &"ab".repeat(32));
    std::fs::create_dir_all(stray_trace.parent().unwrap()).unwrap();
    std::fs::write(&stray_trace, b"\x1f\x8b").unwrap();
    clear_partial_uploads(&f.state).await.unwrap();
    assert_eq!(f.state.sweep_unlinked_files().await.unwrap(), 2);
    assert!(!stray_trace.exists());
    let left = files(&dir);
    assert_eq!(left, vec![file_path(&dir, &kept.sha256)], "stray {stray}");
}
