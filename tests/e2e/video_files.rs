//! Video files on disk across a crash ("no leaked files"): the real server, an
//! on-disk database, and the worker protocol spoken by hand. An upload cut by `kill -9` leaves a
//! partial file in the videos' `tmp/`, which the restarted server removes before it listens; an
//! episode's video uploaded again deletes the file the replaced link named.

use crate::remote_support;
use crate::support;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kitchen_r_contract::server::ServeOptions;
use kitchen_r_proto::worker::v1 as pb;
use pb::worker_client::WorkerClient;
use serde_json::json;
use support::*;
use tokio_stream::wrappers::ReceiverStream;
use tonic::transport::Channel;

/// One-task dev episodes, no offline twin, no in-process workers (the test is the worker).
const CONFIG: &str = "[control]\noffline_mse = false\nmax_plan_steps = 1\n[quota]\nconcurrent_runs = 0\n";

fn authed<T>(msg: T) -> tonic::Request<T> {
    let mut req = tonic::Request::new(msg);
    let bearer = format!("Bearer {WORKER_TOKEN}").parse().unwrap();
    req.metadata_mut().insert("authorization", bearer);
    req
}

async fn worker_client(server: &Server) -> WorkerClient<Channel> {
    WorkerClient::connect(server.grpc.clone()).await.unwrap()
}

/// Lease the one queued job and report that its task ran out of time, as a worker would.
async fn lease_and_report(client: &mut WorkerClient<Channel>) -> pb::Job {
    let lease = pb::LeaseRequest {
        worker_id: "hand-worker".into(),
        max_jobs: 1,
        wait_ms: 5000,
        max_renders: 0,
    };
    let job = client
        .lease(authed(lease))
        .await
        .unwrap()
        .into_inner()
        .jobs
        .remove(0);
    let spec = job.episode.clone().unwrap();
    let steps = match spec.max_plan_steps {
        0 => spec.plan.len(),
        n => spec.plan.len().min(n as usize),
    };
    let tasks = (0..steps)
        .map(|i| pb::TaskResult {
            index: i as u32,
            step: spec.plan[i].clone(),
            failure_reason: "time limit of 120 s reached".into(),
            ..Default::default()
        })
        .collect();
    let report = pb::ReportResultRequest {
        worker_id: "hand-worker".into(),
        job_id: job.job_id,
        attempt: job.attempt,
        run_id: job.run_id,
        episode_key: job.episode_key.clone(),
        result: Some(pb::EpisodeResult {
            tasks,
            wall_ms: 1000,
            ..Default::default()
        }),
    };
    let answer = client.report_result(authed(report)).await.unwrap().into_inner();
    assert!(answer.accepted, "{answer:?}");
    job
}

/// The first chunk of an upload for `job`: names the job and announces `total` bytes.
fn first_chunk(job: &pb::Job, data: Vec<u8>, total: u64) -> pb::VideoChunk {
    pb::VideoChunk {
        job_id: job.job_id,
        attempt: job.attempt,
        run_id: job.run_id,
        episode_key: job.episode_key.clone(),
        worker_id: "hand-worker".into(),
        total_bytes: total,
        data,
        render: false,
    }
}

async fn upload_whole(
    client: &mut WorkerClient<Channel>,
    job: &pb::Job,
    data: Vec<u8>,
) -> pb::UploadVideoResponse {
    let total = data.len() as u64;
    let chunks = tokio_stream::iter(vec![first_chunk(job, data, total)]);
    client.upload_video(authed(chunks)).await.unwrap().into_inner()
}

/// Every file under `dir`, recursively (none when it does not exist).
fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        match e.file_type().unwrap().is_dir() {
            true => out.extend(files_under(&e.path())),
            false => out.push(e.path()),
        }
    }
    out.sort();
    out
}

fn stored(videos: &Path, sha256: &str) -> PathBuf {
    videos.join(&sha256[..2]).join(format!("{sha256}.mp4"))
}

#[test]
fn a_killed_upload_and_a_replaced_video_leave_no_file_behind() {
    use kitchen_r_episode::policy::HORIZON as H;
    use remote_support::{STILL, TestServer, factory};
    // The policy server runs its own runtime: started and dropped outside the test's.
    let policy = TestServer::start(
        factory(H, Arc::new(|_| Ok(vec![STILL; H]))),
        ServeOptions::default(),
    );
    let fx = ControlFixture::new(CONFIG);
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(crash_and_replace(&fx, policy.url()));
}

async fn crash_and_replace(fx: &ControlFixture, policy: String) {
    let videos = fx.dir.path().join("db/videos");
    let tmp = videos.join("tmp");
    let mut server = fx.serve(0);
    let alpha = team(&server, "alpha").await;
    let body = json!({"endpoint": policy, "split": "dev", "episodes": 1});
    let (status, reg) = register_policy(&server, &alpha, body).await;
    assert_eq!(status, 201, "{reg}");
    let id = reg["id"].as_i64().unwrap();
    let mut client = worker_client(&server).await;
    let job = lease_and_report(&mut client).await;
    let first = upload_whole(&mut client, &job, b"first take ".repeat(400)).await;
    let first_file = stored(&videos, &first.sha256);
    assert!(first_file.is_file(), "{:?}", files_under(&videos));

    // Upload the episode's video again, announce 1 MiB, send 64 KiB, and SIGKILL the server
    // once the partial file holds them.
    let (tx, rx) = tokio::sync::mpsc::channel(1);
    tx.send(first_chunk(&job, vec![7; 64 << 10], 1 << 20))
        .await
        .unwrap();
    let mut cut = client.clone();
    let call = tokio::spawn(async move { cut.upload_video(authed(ReceiverStream::new(rx))).await });
    let start = Instant::now();
    while !files_under(&tmp)
        .iter()
        .any(|f| f.metadata().is_ok_and(|m| m.len() >= 64 << 10))
    {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the partial upload never reached disk"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    server.child().kill().unwrap();
    server.child().wait().unwrap();
    assert!(call.await.unwrap().is_err(), "the cut upload succeeded");
    drop(tx);
    let partial = files_under(&tmp);
    assert_eq!(partial.len(), 1, "what the kill left: {partial:?}");
    drop(server);

    // The restarted server (same database and directory) has cleared tmp/ by the time it
    // listens.
    let server = fx.serve(0);
    assert_eq!(
        files_under(&tmp),
        Vec::<PathBuf>::new(),
        "a partial upload survived the restart"
    );

    // A whole new take replaces the link: the first take's file goes.
    let mut client = worker_client(&server).await;
    let second = upload_whole(&mut client, &job, b"second take ".repeat(400)).await;
    assert_ne!(first.sha256, second.sha256);
    assert!(!first_file.exists(), "the replaced video's file is still on disk");
    assert_eq!(files_under(&videos), vec![stored(&videos, &second.sha256)]);
    let (_, v) = get_json(&server, &format!("/api/v1/submissions/{id}"), Some(&alpha)).await;
    let ep = &v["latest_run"]["evaluation"]["episodes"][0];
    assert!(ep["video_url"].is_string(), "{ep:#}");
}
