use kitchen_r_core::dataset::Split;
use kitchen_r_proto::worker::v1 as pb;
use sha2::{Digest, Sha256};
use tonic::{Code, Request};

use super::*;
use crate::testutil::{FakeProbe, Fixture, WORKER, fixture};

mod budget;
mod fair;
mod renders;

/// `(job id, attempt, run, key)` of every reported online job, dev run first.
pub(super) async fn done_jobs(f: &Fixture) -> Vec<(i64, i64, i64, String)> {
    sqlx::query_as(
        "SELECT id, attempt, run_id, episode_key FROM jobs WHERE state = 'done'
         AND episode_key NOT LIKE '%/offline' ORDER BY run_id, id",
    )
    .fetch_all(f.state.pool())
    .await
    .unwrap()
}

/// The upload stream of `data` for `job`, in chunks of 3 bytes, announcing `total` bytes.
pub(super) fn upload(
    job: &(i64, i64, i64, String),
    data: &[u8],
    total: u64,
) -> Request<tokio_stream::Iter<std::vec::IntoIter<pb::VideoChunk>>> {
    let mut chunks: Vec<pb::VideoChunk> = data
        .chunks(3)
        .map(|d| pb::VideoChunk {
            data: d.to_vec(),
            ..Default::default()
        })
        .collect();
    let first = &mut chunks[0];
    (first.job_id, first.attempt, first.run_id) = (job.0, job.1 as u32, job.2);
    first.episode_key = job.3.clone();
    first.worker_id = "w1".into();
    first.total_bytes = total;
    let mut req = Request::new(tokio_stream::iter(chunks));
    req.metadata_mut()
        .insert("authorization", format!("Bearer {WORKER}").parse().unwrap());
    req
}

pub(super) fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(files(&p));
        } else {
            out.push(p);
        }
    }
    out
}

#[tokio::test]
async fn uploads_are_stored_once_by_content_and_shown_only_to_who_may_see_the_episode() {
    let f = fixture(FakeProbe::ok(8), |c| c.control.dev_episodes = 1).await;
    let (alpha, bravo, dev, test) = f.runs_with_paths(|_| Default::default()).await;
    let mut client = f.worker_client().await;
    let jobs = done_jobs(&f).await;
    let (dev_job, test_job) = (&jobs[0], jobs.last().unwrap());
    assert_ne!(dev_job.2, test_job.2, "{jobs:?}");
    let mp4 = b"not really an mp4, but bytes".to_vec();
    let answer = client
        .upload_video(upload(dev_job, &mp4, mp4.len() as u64))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(answer.sha256, hex::encode(Sha256::digest(&mp4)));
    assert_eq!(answer.bytes, mp4.len() as u64);
    // The same bytes for another episode: linked, not stored twice.
    client
        .upload_video(upload(test_job, &mp4, mp4.len() as u64))
        .await
        .unwrap();
    let dir = f.state.video_dir().unwrap();
    assert_eq!(files(&dir), vec![file_path(&dir, &answer.sha256)]);

    // A job that reported nothing, a stream shorter or longer than announced: refused, no file.
    let stranger = (dev_job.0, dev_job.1 + 1, dev_job.2, dev_job.3.clone());
    let e = client
        .upload_video(upload(&stranger, &mp4, mp4.len() as u64))
        .await
        .unwrap_err();
    assert_eq!(e.code(), Code::FailedPrecondition, "{e:?}");
    let e = client
        .upload_video(upload(dev_job, &mp4, mp4.len() as u64 + 1))
        .await
        .unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
    let e = client.upload_video(upload(dev_job, &mp4, 4)).await.unwrap_err();
    assert_eq!(e.code(), Code::InvalidArgument, "{e:?}");
    assert_eq!(
        files(&dir).len(),
        1,
        "a refused upload left a file: {:?}",
        files(&dir)
    );

    let key = &dev_job.3;
    let own = f.caller(&alpha).await;
    let v = f.state.episode_video(&own, dev, key).await.unwrap();
    assert_eq!(std::fs::read(&v.path).unwrap(), mp4);
    let other = f.caller(&bravo).await;
    let not_found = |r: Result<StoredVideo, ServiceError>| matches!(r, Err(ServiceError::NotFound { .. }));
    assert!(not_found(f.state.episode_video(&other, dev, key).await));
    // Test split: recorded and stored, shown to the organiser only.
    assert!(not_found(f.state.episode_video(&own, test, &test_job.3).await));
    let organiser = Caller::Organiser(f.admin().await);
    assert!(f.state.episode_video(&organiser, test, &test_job.3).await.is_ok());
    assert!(f.state.episode_video(&organiser, dev, key).await.is_ok());
    // The submission JSON links the dev video, never a test one.
    let view = f.state.get_submission(&own, dev).await.unwrap();
    let eps = view.latest_run.unwrap().evaluation.unwrap().episodes;
    let url = eps.iter().find(|e| &e.key == key).unwrap().video_url.clone();
    assert_eq!(
        url.unwrap(),
        format!("/api/v1/submissions/{dev}/episodes/{key}/video.mp4")
    );
    let view = f.state.get_submission(&organiser, test).await.unwrap();
    let eps = view.latest_run.unwrap().evaluation.unwrap().episodes;
    assert!(eps.iter().all(|e| e.video_url.is_none()));
}

#[tokio::test]
async fn the_retention_sweep_deletes_old_links_and_files_no_link_names() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.dev_episodes = 1;
        c.video.retention_days = 2;
    })
    .await;
    f.runs_with_paths(|_| Default::default()).await;
    let jobs = done_jobs(&f).await;
    let dir = f.state.video_dir().unwrap();
    let (old, shared) = (store_file(&dir, b"old").await, store_file(&dir, b"shared").await);
    let now = 100 * DAY_MS;
    let (a, b) = (&jobs[0], jobs.last().unwrap());
    let pool = f.state.pool();
    let link = |run: i64, key: String, sha: String, at: i64| async move {
        let (team, _) = store::videos::team_of_run(pool, run).await.unwrap().unwrap();
        let row = store::videos::Row {
            run,
            key: &key,
            team,
            now: at,
        };
        store::videos::link(pool, row, &sha, 3).await.unwrap();
    };
    link(a.2, a.3.clone(), old.clone(), now - 3 * DAY_MS).await;
    // `shared` is linked by an old row and a recent one: the file stays.
    link(b.2, b.3.clone(), shared.clone(), now - 3 * DAY_MS).await;
    link(a.2, "other-key".into(), shared.clone(), now - DAY_MS).await;
    assert_eq!(f.state.sweep_videos(now).await.unwrap(), 1);
    assert!(!file_path(&dir, &old).exists());
    assert!(file_path(&dir, &shared).exists());
    assert!(store::videos::video(pool, a.2, &a.3).await.unwrap().is_none());
    assert!(
        store::videos::video(pool, a.2, "other-key")
            .await
            .unwrap()
            .is_some()
    );
    // retention_days = 0 keeps everything.
    let keep = fixture(FakeProbe::ok(8), |c| c.video.retention_days = 0).await;
    assert_eq!(keep.state.sweep_videos(now).await.unwrap(), 0);
}

/// Store `bytes` as a finished upload would; returns its sha256.
pub(crate) async fn store_file(dir: &Path, bytes: &[u8]) -> String {
    let mut up = Incoming::start(dir, bytes.len() as u64, 1 << 20).await.unwrap();
    up.write(bytes).await.unwrap();
    let done = up.finish().await.unwrap();
    let sha = done.sha256.clone();
    done.place(dir).await.unwrap();
    sha
}

#[tokio::test]
async fn turning_videos_off_stops_recording_and_serving() {
    let f = fixture(FakeProbe::ok(8), |c| {
        c.control.dev_episodes = 1;
        c.video.enabled = false;
    })
    .await;
    let token = f.team("alpha").await;
    let caller = f.caller(&token).await;
    f.state
        .register_policy(&caller, f.request(Split::Dev))
        .await
        .unwrap();
    assert!(f.state.video_dir().is_none());
    let mut client = f.worker_client().await;
    let jobs = client.lease(lease(4)).await.unwrap().into_inner().jobs;
    assert!(!jobs.is_empty());
    assert!(jobs.iter().all(|j| !j.episode.as_ref().unwrap().record_video));
}

/// A worker's lease of up to `max_jobs` jobs, not waiting.
fn lease(max_jobs: u32) -> Request<pb::LeaseRequest> {
    let mut req = Request::new(pb::LeaseRequest {
        worker_id: "w1".into(),
        max_jobs,
        wait_ms: 0,
        max_renders: 0,
    });
    req.metadata_mut()
        .insert("authorization", format!("Bearer {WORKER}").parse().unwrap());
    req
}

/// Which leased jobs ask for a video: `(dev jobs recording, test jobs recording, test jobs)`.
async fn recording(test_split: bool) -> (usize, usize, usize) {
    let f = fixture(FakeProbe::ok(64), |c| {
        c.control.dev_episodes = 1;
        c.control.offline_mse = false;
        c.quota.concurrent_runs = 0;
        c.video.test_split = test_split;
    })
    .await;
    let token = f.team("alpha").await;
    let caller = f.caller(&token).await;
    for split in [Split::Dev, Split::Test] {
        f.state.register_policy(&caller, f.request(split)).await.unwrap();
    }
    let mut client = f.worker_client().await;
    let (mut dev, mut test, mut tests) = (0, 0, 0);
    loop {
        let jobs = client.lease(lease(64)).await.unwrap().into_inner().jobs;
        if jobs.is_empty() {
            break;
        }
        for j in jobs {
            let on = j.episode.as_ref().unwrap().record_video;
            if f.state
                .content()
                .is_test(&j.episode.as_ref().unwrap().instruction_id)
            {
                tests += 1;
                test += usize::from(on);
            } else {
                dev += usize::from(on);
            }
        }
    }
    (dev, test, tests)
}

#[tokio::test]
async fn test_split_episodes_are_recorded_only_when_the_organiser_asks() {
    let (dev, test, tests) = recording(false).await;
    assert_eq!((dev, test), (1, 0), "default: dev recorded, test not");
    assert!(tests > 0, "the test run leased its jobs");
    let (dev, test, tests) = recording(true).await;
    assert_eq!(
        (dev, test),
        (1, tests),
        "[video] test_split = true records every test episode"
    );
}
