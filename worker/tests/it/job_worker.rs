//! The worker loop against a small in-test `kitchen_r.worker.v1.Worker` server on 127.0.0.1:0:
//! two jobs handed out, heartbeats while they run, the first report failed by the server and
//! retried, the token checked, a clean stop on shutdown, draining, and episodes that wait on
//! their policy without holding a slot.

use crate::remote_support;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use kitchen_r_episode::policy::HORIZON;
use kitchen_r_proto::worker::v1 as pb;
use kitchen_r_worker::job::{WorkerConfig, WorkerError, run_worker};
use pb::worker_server::{Worker, WorkerServer};
use remote_support::*;
use tonic::{Request, Response, Status};

#[derive(Default)]
struct State {
    queue: Vec<pb::Job>,
    heartbeats: Vec<(i64, u32)>,
    report_calls: u32,
    reports: Vec<pb::ReportResultRequest>,
    lease_workers: Vec<String>,
    releases: Vec<pb::ReleaseRequest>,
    /// Hold a Lease answer this long after taking its job off the queue.
    lease_delay: Duration,
    /// The most jobs one Lease call asked for.
    max_jobs_asked: u32,
    /// Episode videos uploaded: the first chunk (with no data) and the joined bytes, with how
    /// many reports had arrived when each upload began.
    videos: Vec<(pb::VideoChunk, Vec<u8>, usize)>,
    upload_calls: u32,
    /// Episode traces uploaded (videos on demand): the first chunk and the joined bytes.
    traces: Vec<(pb::TraceChunk, Vec<u8>)>,
    /// Render jobs reported failed.
    render_failures: Vec<pb::FailRenderRequest>,
    /// Heartbeats of render leases: (render id, progress).
    render_heartbeats: Vec<(i64, f32)>,
    /// What `FetchTrace` streams, per render id, in chunks of 64 KiB.
    fetchable: std::collections::HashMap<i64, Vec<u8>>,
}

#[derive(Clone)]
struct TestWorkerServer(Arc<Mutex<State>>);

fn now_ms() -> i64 {
    SystemTime::now().duration_since(UNIX_EPOCH).unwrap().as_millis() as i64
}

fn authed<T>(req: &Request<T>) -> Result<(), Status> {
    match req.metadata().get("authorization").and_then(|v| v.to_str().ok()) {
        Some("Bearer worker-secret") => Ok(()),
        _ => Err(Status::unauthenticated("bad worker token")),
    }
}

#[tonic::async_trait]
impl Worker for TestWorkerServer {
    async fn lease(&self, req: Request<pb::LeaseRequest>) -> Result<Response<pb::LeaseResponse>, Status> {
        authed(&req)?;
        let r = req.into_inner();
        assert!((1..=64).contains(&r.max_jobs), "{}", r.max_jobs);
        let (mut jobs, delay) = {
            let mut s = self.0.lock().unwrap();
            s.lease_workers.push(r.worker_id);
            s.max_jobs_asked = s.max_jobs_asked.max(r.max_jobs);
            let n = s.queue.len().min(r.max_jobs as usize);
            let at = s.queue.len() - n;
            (s.queue.split_off(at), s.lease_delay)
        };
        if jobs.is_empty() {
            tokio::time::sleep(Duration::from_millis(u64::from(r.wait_ms.min(200)))).await;
        } else {
            tokio::time::sleep(delay).await;
        }
        for j in &mut jobs {
            j.lease_expires_at_ms = now_ms() + 1_500;
        }
        Ok(Response::new(pb::LeaseResponse { jobs }))
    }

    async fn heartbeat(
        &self,
        req: Request<pb::HeartbeatRequest>,
    ) -> Result<Response<pb::HeartbeatResponse>, Status> {
        authed(&req)?;
        let r = req.into_inner();
        let mut s = self.0.lock().unwrap();
        match r.render {
            true => s.render_heartbeats.push((r.job_id, r.progress)),
            false => s.heartbeats.push((r.job_id, r.attempt)),
        }
        Ok(Response::new(pb::HeartbeatResponse {
            lease_expires_at_ms: now_ms() + 1_500,
            cancelled: false,
        }))
    }

    async fn release(
        &self,
        req: Request<pb::ReleaseRequest>,
    ) -> Result<Response<pb::ReleaseResponse>, Status> {
        authed(&req)?;
        self.0.lock().unwrap().releases.push(req.into_inner());
        Ok(Response::new(pb::ReleaseResponse { released: true }))
    }

    async fn report_result(
        &self,
        req: Request<pb::ReportResultRequest>,
    ) -> Result<Response<pb::ReportResultResponse>, Status> {
        authed(&req)?;
        let mut s = self.0.lock().unwrap();
        s.report_calls += 1;
        if s.report_calls == 1 {
            return Err(Status::unavailable("the database is restarting"));
        }
        s.reports.push(req.into_inner());
        Ok(Response::new(pb::ReportResultResponse {
            accepted: true,
            duplicate: false,
        }))
    }

    async fn upload_video(
        &self,
        req: Request<tonic::Streaming<pb::VideoChunk>>,
    ) -> Result<Response<pb::UploadVideoResponse>, Status> {
        authed(&req)?;
        let reports = {
            let mut s = self.0.lock().unwrap();
            s.upload_calls += 1;
            if s.upload_calls == 1 {
                return Err(Status::unavailable("the disk is busy"));
            }
            s.reports.len()
        };
        let mut stream = req.into_inner();
        let mut first: Option<pb::VideoChunk> = None;
        let mut bytes = Vec::new();
        while let Some(mut c) = stream.message().await? {
            bytes.append(&mut c.data);
            first.get_or_insert(c);
        }
        let first = first.ok_or_else(|| Status::invalid_argument("empty"))?;
        let n = bytes.len() as u64;
        self.0.lock().unwrap().videos.push((first, bytes, reports));
        Ok(Response::new(pb::UploadVideoResponse {
            sha256: String::new(),
            bytes: n,
        }))
    }

    async fn upload_trace(
        &self,
        req: Request<tonic::Streaming<pb::TraceChunk>>,
    ) -> Result<Response<pb::UploadTraceResponse>, Status> {
        authed(&req)?;
        let mut stream = req.into_inner();
        let mut first: Option<pb::TraceChunk> = None;
        let mut bytes = Vec::new();
        while let Some(mut c) = stream.message().await? {
            bytes.append(&mut c.data);
            first.get_or_insert(c);
        }
        let first = first.ok_or_else(|| Status::invalid_argument("empty"))?;
        let n = bytes.len() as u64;
        self.0.lock().unwrap().traces.push((first, bytes));
        Ok(Response::new(pb::UploadTraceResponse {
            sha256: String::new(),
            bytes: n,
        }))
    }

    type FetchTraceStream =
        std::pin::Pin<Box<dyn tokio_stream::Stream<Item = Result<pb::TraceChunk, Status>> + Send>>;

    async fn fetch_trace(
        &self,
        req: Request<pb::FetchTraceRequest>,
    ) -> Result<Response<Self::FetchTraceStream>, Status> {
        authed(&req)?;
        let id = req.into_inner().render_id;
        let bytes = (self.0.lock().unwrap().fetchable.get(&id).cloned())
            .ok_or_else(|| Status::not_found(format!("no trace for render {id}")))?;
        let total_bytes = bytes.len() as u64;
        let chunks: Vec<Result<pb::TraceChunk, Status>> = (bytes.chunks(64 << 10).enumerate())
            .map(|(i, d)| {
                Ok(pb::TraceChunk {
                    data: d.to_vec(),
                    total_bytes: if i == 0 { total_bytes } else { 0 },
                    ..Default::default()
                })
            })
            .collect();
        Ok(Response::new(Box::pin(tokio_stream::iter(chunks))))
    }

    async fn fail_render(
        &self,
        req: Request<pb::FailRenderRequest>,
    ) -> Result<Response<pb::FailRenderResponse>, Status> {
        authed(&req)?;
        self.0.lock().unwrap().render_failures.push(req.into_inner());
        Ok(Response::new(pb::FailRenderResponse { accepted: true }))
    }
}

fn start(state: Arc<Mutex<State>>, rt: &tokio::runtime::Runtime) -> String {
    let listener = rt.block_on(tokio::net::TcpListener::bind("127.0.0.1:0")).unwrap();
    let addr = listener.local_addr().unwrap();
    rt.spawn(
        tonic::transport::Server::builder()
            .add_service(WorkerServer::new(TestWorkerServer(state)))
            .serve_with_incoming(tokio_stream::wrappers::TcpListenerStream::new(listener)),
    );
    format!("http://{addr}")
}

/// A slow policy (so heartbeats fall inside the episode) that never completes a task.
fn slow_still() -> TestServer {
    TestServer::start(
        factory(
            HORIZON,
            Arc::new(|_| {
                std::thread::sleep(Duration::from_millis(400));
                Ok(vec![STILL; HORIZON])
            }),
        ),
        Default::default(),
    )
}

fn job(id: i64, policy: &str) -> pb::Job {
    let data = kitchen_r_core::dataset::Dataset::load(&kitchen_r_core::assets::assets_dir().join("dataset"))
        .unwrap();
    let ins = &data.dev[(id as usize) % 3];
    pb::Job {
        job_id: id,
        attempt: 1,
        // Leased for 1.5 s: the worker heartbeats every 0.5 s, well inside one job (two policy
        // calls of 0.4 s each), however fast the simulation runs.
        lease_expires_at_ms: now_ms() + 1_500,
        run_id: 1,
        episode_key: ins.id.clone(),
        episode: Some(pb::EpisodeSpec {
            scene_id: ins.scene.clone(),
            instruction_id: ins.id.clone(),
            plan: ins.plan.clone(),
            seed: 5,
            mode: pb::EvalMode::Online as i32,
            task_time_limit_s: 2.0,
            actions_executed_per_chunk: 8,
            teleport_on_failure: false,
            max_plan_steps: 1,
            privileged: false,
            place_targets: ins.place_targets.iter().map(pb::PlaceTarget::from).collect(),
            policy_episode_id: String::new(),
            record_video: false,
            video_on_demand: false,
            video_max_bytes: 0,
            privileged_observations: 0,
            grasp_mode: 0,
            live_ros2: false,
        }),
        policy: Some(pb::PolicyEndpoint {
            url: policy.to_string(),
            call_deadline_ms: 5_000,
            startup_deadline_ms: 5_000,
            ..Default::default()
        }),
        render: None,
    }
}

fn config(server: &str, token: &str) -> WorkerConfig {
    WorkerConfig {
        server: server.to_string(),
        token: token.to_string(),
        slots: 2,
        worker_id: "test-worker".into(),
        lease_wait_ms: 200,
        ..WorkerConfig::default()
    }
}

#[test]
fn two_jobs_are_run_heartbeated_and_reported_despite_a_failed_report() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let policy = slow_still();
    let state = Arc::new(Mutex::new(State {
        queue: vec![job(1, &policy.url()), job(2, &policy.url())],
        ..State::default()
    }));
    let url = start(state.clone(), &rt);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let worker = rt.spawn(run_worker(config(&url, "worker-secret"), async {
        let _ = stop_rx.await;
    }));
    let t = Instant::now();
    while state.lock().unwrap().reports.len() < 2 {
        assert!(t.elapsed() < Duration::from_secs(120), "reports never arrived");
        std::thread::sleep(Duration::from_millis(100));
    }
    stop_tx.send(()).unwrap();
    rt.block_on(worker).unwrap().unwrap();

    let s = state.lock().unwrap();
    assert_eq!(s.report_calls, 3, "the failed report is retried once");
    let mut ids: Vec<i64> = s.reports.iter().map(|r| r.job_id).collect();
    ids.sort_unstable();
    assert_eq!(ids, [1, 2]);
    for r in &s.reports {
        let res = r.result.as_ref().unwrap();
        assert_eq!(res.platform_error, "", "{}", res.log_tail);
        assert_eq!(res.tasks.len(), 1);
        assert!(
            res.tasks[0].failure_reason.contains("time limit of 2 s"),
            "{:?}",
            res.tasks
        );
        assert_eq!((r.run_id, r.attempt, r.worker_id.as_str()), (1, 1, "test-worker"));
    }
    for id in [1, 2] {
        assert!(
            s.heartbeats.contains(&(id, 1)),
            "no heartbeat for job {id}: {:?}",
            s.heartbeats
        );
    }
    assert!(s.lease_workers.iter().all(|w| w == "test-worker"));
}

#[test]
fn a_refused_token_stops_the_worker_with_a_clear_error() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let state = Arc::new(Mutex::new(State::default()));
    let url = start(state, &rt);
    let r = rt.block_on(async {
        tokio::time::timeout(
            Duration::from_secs(60),
            run_worker(config(&url, "wrong"), std::future::pending()),
        )
        .await
    });
    let err = r.expect("the worker should stop").unwrap_err();
    assert!(matches!(err, WorkerError::Refused(_)), "{err:?}");
    assert!(err.to_string().contains("worker token"), "{err}");
}

#[test]
fn a_server_that_is_down_is_retried_until_shutdown() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let free = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap();
    let t = Instant::now();
    let r = rt.block_on(run_worker(
        config(&format!("http://{free}"), "worker-secret"),
        async {
            tokio::time::sleep(Duration::from_secs(2)).await;
        },
    ));
    assert!(r.is_ok(), "{r:?}");
    assert!(t.elapsed() >= Duration::from_secs(2), "the worker gave up early");
}

/// Start a worker on two jobs of the slow policy with `grace` seconds to drain, stop it once
/// both are running, and return the server's state after it exited, how long it took, and how
/// many Lease calls had come by the stop.
fn drain(grace: u64) -> (Arc<Mutex<State>>, Duration, usize) {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let policy = slow_still();
    let state = Arc::new(Mutex::new(State {
        queue: vec![job(1, &policy.url()), job(2, &policy.url())],
        // The first report fails once (see `report_result`): count it as done already.
        report_calls: 1,
        ..State::default()
    }));
    let url = start(state.clone(), &rt);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let cfg = WorkerConfig {
        drain_grace_s: grace,
        ..config(&url, "worker-secret")
    };
    let worker = rt.spawn(run_worker(cfg, async {
        let _ = stop_rx.await;
    }));
    // Both episodes are running once both have heartbeated.
    let t = Instant::now();
    while !{
        let s = state.lock().unwrap();
        s.heartbeats.iter().any(|h| h.0 == 1) && s.heartbeats.iter().any(|h| h.0 == 2)
    } {
        assert!(t.elapsed() < Duration::from_secs(60), "jobs never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    let stopped = Instant::now();
    let leases = state.lock().unwrap().lease_workers.len();
    stop_tx.send(()).unwrap();
    rt.block_on(worker).unwrap().unwrap();
    (state, stopped.elapsed(), leases)
}

#[test]
fn a_draining_worker_with_no_grace_releases_its_running_episodes_at_once() {
    let (state, took, leases) = drain(0);
    let s = state.lock().unwrap();
    assert!(s.reports.is_empty(), "nothing reported: {:?}", s.reports);
    let mut ids: Vec<(i64, u32)> = s.releases.iter().map(|r| (r.job_id, r.attempt)).collect();
    ids.sort_unstable();
    assert_eq!(ids, [(1, 1), (2, 1)]);
    assert!(
        s.releases
            .iter()
            .all(|r| r.worker_id == "test-worker" && r.reason.contains("draining"))
    );
    assert!(took < Duration::from_secs(10), "{took:?}");
    // No Lease call after the stop (one may have been on its way).
    assert!(
        s.lease_workers.len() <= leases + 1,
        "{leases} then {:?}",
        s.lease_workers
    );
}

#[test]
fn a_draining_worker_finishes_its_running_episodes_within_the_grace_period() {
    let (state, _, _) = drain(120);
    let s = state.lock().unwrap();
    assert!(s.releases.is_empty(), "nothing released: {:?}", s.releases);
    let mut ids: Vec<i64> = s.reports.iter().map(|r| r.job_id).collect();
    ids.sort_unstable();
    assert_eq!(ids, [1, 2], "both episodes ran to the end and were reported");
    for r in &s.reports {
        let res = r.result.as_ref().unwrap();
        assert_eq!(res.platform_error, "", "{}", res.log_tail);
        assert_eq!(res.tasks.len(), 1);
    }
}

#[test]
fn a_job_leased_as_the_worker_stops_is_released_not_left_to_expire() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let policy = slow_still();
    let state = Arc::new(Mutex::new(State {
        queue: vec![job(1, &policy.url())],
        lease_delay: Duration::from_millis(300),
        ..State::default()
    }));
    let url = start(state.clone(), &rt);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let cfg = WorkerConfig {
        slots: 1,
        ..config(&url, "worker-secret")
    };
    let worker = rt.spawn(run_worker(cfg, async {
        let _ = stop_rx.await;
    }));
    // The server has taken the job for the worker's Lease and answers 300 ms later.
    let t = Instant::now();
    while !state.lock().unwrap().queue.is_empty() {
        assert!(t.elapsed() < Duration::from_secs(60), "never leased");
        std::thread::sleep(Duration::from_millis(5));
    }
    stop_tx.send(()).unwrap();
    rt.block_on(worker).unwrap().unwrap();
    let s = state.lock().unwrap();
    assert!(
        s.reports.is_empty() && s.heartbeats.is_empty(),
        "the job was not run"
    );
    assert_eq!(s.releases.len(), 1, "{:?}", s.releases);
    assert_eq!((s.releases[0].job_id, s.releases[0].attempt), (1, 1));
    assert!(s.releases[0].reason.contains("stopped"), "{:?}", s.releases[0]);
}

#[test]
fn episodes_waiting_on_a_slow_policy_share_one_slot() {
    // Each act takes 200 ms; the simulation of a chunk takes a few. With one slot, a worker that
    // kept the slot for the whole episode would call the policy for one episode at a time.
    let (now, peak) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
    let (n, p) = (now.clone(), peak.clone());
    let policy = TestServer::start(
        factory(
            HORIZON,
            Arc::new(move |_| {
                p.fetch_max(n.fetch_add(1, Ordering::SeqCst) + 1, Ordering::SeqCst);
                std::thread::sleep(Duration::from_millis(200));
                n.fetch_sub(1, Ordering::SeqCst);
                Ok(vec![STILL; HORIZON])
            }),
        ),
        Default::default(),
    );
    let rt = tokio::runtime::Runtime::new().unwrap();
    let state = Arc::new(Mutex::new(State {
        queue: (1..=6).map(|id| job(id, &policy.url())).collect(),
        // The first report fails once (see `report_result`): count it as done already.
        report_calls: 1,
        ..State::default()
    }));
    let url = start(state.clone(), &rt);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let cfg = WorkerConfig {
        slots: 1,
        max_episodes: 4,
        ..config(&url, "worker-secret")
    };
    let worker = rt.spawn(run_worker(cfg, async {
        let _ = stop_rx.await;
    }));
    let t = Instant::now();
    while state.lock().unwrap().reports.len() < 6 {
        assert!(t.elapsed() < Duration::from_secs(120), "reports never arrived");
        std::thread::sleep(Duration::from_millis(50));
    }
    stop_tx.send(()).unwrap();
    rt.block_on(worker).unwrap().unwrap();
    let peak = peak.load(Ordering::SeqCst);
    assert!(
        (2..=4).contains(&peak),
        "{peak} episodes waited on the policy at once (1 slot, max_episodes 4)"
    );
    let s = state.lock().unwrap();
    assert!(
        s.max_jobs_asked <= 4,
        "asked for {} jobs at once",
        s.max_jobs_asked
    );
    for r in &s.reports {
        let res = r.result.as_ref().unwrap();
        assert_eq!(res.platform_error, "", "{}", res.log_tail);
        assert!(
            res.tasks[0].failure_reason.contains("time limit of 2 s"),
            "{:?}",
            res.tasks
        );
    }
}

/// The standalone worker's video path: a job that asks for a video gets its MP4 uploaded in
/// chunks over `UploadVideo` after its result is reported, and a failed upload is retried.
#[test]
fn a_recorded_episode_video_is_uploaded_in_chunks_after_its_report() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let policy = slow_still();
    let mut recorded = job(1, &policy.url());
    if let Some(e) = recorded.episode.as_mut() {
        e.record_video = true;
    }
    let state = Arc::new(Mutex::new(State {
        queue: vec![recorded],
        ..State::default()
    }));
    let url = start(state.clone(), &rt);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let worker = rt.spawn(run_worker(config(&url, "worker-secret"), async {
        let _ = stop_rx.await;
    }));
    let t = Instant::now();
    while state.lock().unwrap().videos.is_empty() {
        assert!(t.elapsed() < Duration::from_secs(120), "the video never arrived");
        std::thread::sleep(Duration::from_millis(100));
    }
    stop_tx.send(()).unwrap();
    rt.block_on(worker).unwrap().unwrap();
    let s = state.lock().unwrap();
    assert_eq!(s.upload_calls, 2, "the failed upload is retried once");
    let (first, mp4, reports_before) = &s.videos[0];
    assert_eq!(
        *reports_before, 1,
        "the result is reported before the video is sent"
    );
    assert_eq!((first.job_id, first.attempt, first.run_id), (1, 1, 1));
    assert_eq!(first.worker_id, "test-worker");
    assert_eq!(first.total_bytes, mp4.len() as u64);
    assert_eq!(&mp4[4..8], b"ftyp");
    let log = &s.reports[0].result.as_ref().unwrap().log_tail;
    assert!(log.contains("video: 20 frames"), "{log}");
}

/// Videos on demand (docs/contest/video.md): a job that wants its video on demand uploads its
/// trace, not a video, after its report; a render job of that trace uploads the video (marked
/// `render`) with its progress heartbeated; a render job whose stored result disagrees with the
/// replay is reported failed and uploads nothing.
#[test]
fn an_on_demand_episode_uploads_its_trace_and_a_render_job_makes_its_video_or_refuses() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let policy = slow_still();
    let mut on_demand = job(1, &policy.url());
    if let Some(e) = on_demand.episode.as_mut() {
        e.record_video = true;
        e.video_on_demand = true;
    }
    let state = Arc::new(Mutex::new(State {
        queue: vec![on_demand],
        ..State::default()
    }));
    let url = start(state.clone(), &rt);
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let worker = rt.spawn(run_worker(config(&url, "worker-secret"), async {
        let _ = stop_rx.await;
    }));
    let wait = |what: &str, done: &dyn Fn(&State) -> bool| {
        let t = Instant::now();
        while !done(&state.lock().unwrap()) {
            assert!(t.elapsed() < Duration::from_secs(120), "{what} never happened");
            std::thread::sleep(Duration::from_millis(100));
        }
    };
    wait("the trace upload", &|s| !s.traces.is_empty());
    let (gz, tasks) = {
        let s = state.lock().unwrap();
        assert!(s.videos.is_empty(), "a video was rendered during evaluation");
        assert_eq!(
            s.reports.len(),
            1,
            "the result is reported before the trace is sent"
        );
        let (first, gz) = s.traces[0].clone();
        assert_eq!(
            (first.job_id, first.run_id, first.total_bytes),
            (1, 1, gz.len() as u64)
        );
        assert_eq!(&gz[..2], &[0x1f, 0x8b], "gzipped");
        let log = &s.reports[0].result.as_ref().unwrap().log_tail;
        assert!(!log.contains("video:"), "{log}");
        (gz, s.reports[0].result.as_ref().unwrap().tasks.clone())
    };
    let render = |id: i64, expected: Vec<pb::TaskResult>| pb::Job {
        job_id: id,
        attempt: 1,
        lease_expires_at_ms: now_ms() + 1_500,
        run_id: 1,
        episode_key: "dev-0001".into(),
        episode: None,
        policy: None,
        // Named, not carried: the worker fetches it with FetchTrace, in chunks.
        render: Some(pb::RenderJob {
            trace_gz: Vec::new(),
            expected,
            video_max_bytes: 0,
            trace_bytes: gz.len() as u64,
            trace_sha256: hex::encode(<sha2::Sha256 as sha2::Digest>::digest(&gz)),
        }),
    };
    let mut tampered = tasks.clone();
    tampered[0].success = !tampered[0].success;
    tampered[0].completion_time_s = 1.0;
    {
        let mut s = state.lock().unwrap();
        s.fetchable.insert(50, gz.clone());
        s.fetchable.insert(51, gz.clone());
        // A trace that arrives other than its render job names it: never replayed.
        let mut altered = gz.clone();
        *altered.last_mut().unwrap() ^= 1;
        s.fetchable.insert(52, altered);
        s.queue.push(render(50, tasks.clone()));
        s.queue.push(render(51, tampered));
        s.queue.push(render(52, tasks));
    }
    wait("the render", &|s| {
        !s.videos.is_empty() && s.render_failures.len() >= 2
    });
    stop_tx.send(()).unwrap();
    rt.block_on(worker).unwrap().unwrap();
    let s = state.lock().unwrap();
    let (first, mp4, _) = &s.videos[0];
    assert!(first.render && first.job_id == 50, "{first:?}");
    assert_eq!(&mp4[4..8], b"ftyp");
    assert_eq!(s.videos.len(), 1, "the refused render uploaded a video");
    let failed = |id: i64| {
        &s.render_failures
            .iter()
            .find(|f| f.render_id == id)
            .unwrap()
            .error
    };
    assert!(
        failed(51).contains("replay disagrees with the stored result"),
        "{}",
        failed(51)
    );
    assert!(failed(52).contains("arrived altered"), "{}", failed(52));
}
