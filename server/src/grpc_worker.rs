//! The gRPC adapter (tonic) for `kitchen_r.worker.v1.Worker`: simulation workers lease jobs,
//! heartbeat, report results and release unfinished jobs here. Served on the same port as the
//! participant API.
//!
//! Only conversion lives here; the queue's rules are in [`crate::service::jobs`]. Every call
//! needs `authorization: Bearer <worker token>` (UNAUTHENTICATED otherwise).

use kitchen_r_proto::worker::v1 as pb;
use pb::worker_server::Worker;
use tonic::{Request, Response, Status};

use crate::config::{LiveConfig, VideoConfig};
use crate::episodes::TaskOutcome;
use crate::grpc::caller;
use crate::service::AppState;
use crate::service::jobs::{LeasedJob, Report};
use crate::service::renders::LeasedRender;

#[derive(Debug, Clone)]
pub(crate) struct WorkerService {
    state: AppState,
}

impl WorkerService {
    pub(crate) fn new(state: AppState) -> Self {
        WorkerService { state }
    }

    pub(crate) fn into_server(self) -> pb::worker_server::WorkerServer<Self> {
        // Reports carry a log tail of up to 64 KiB plus task results; leave room.
        pb::worker_server::WorkerServer::new(self).max_decoding_message_size(1 << 20)
    }
}

/// A leased job on the wire; whether to record a video is the server's `[video]` setting now,
/// not stored with the job, so the organiser can turn it off for queued work too. `test` says
/// the episode is of the test split (recorded only with `[video] test_split`). The video is
/// always wanted on demand (docs/contest/video.md): the worker uploads the trace, and a render job
/// makes the video when it is first asked for. Live ROS 2 publishing (`[live] ros2`) is likewise
/// decided here at lease, and never for a test-split episode: its topics would show the hidden
/// plan's sub-tasks and where the robot was sent.
fn job(j: LeasedJob, (video, live): (&VideoConfig, &LiveConfig), store_ok: bool, test: bool) -> pb::Job {
    let mut episode = j.spec.episode_proto(&j.policy_episode_id);
    let online = episode.mode == pb::EvalMode::Online as i32;
    episode.record_video = video.enabled && store_ok && (video.test_split || !test) && online;
    episode.video_on_demand = episode.record_video;
    episode.video_max_bytes = video.max_bytes;
    episode.live_ros2 = live.ros2 && !test && online;
    pb::Job {
        job_id: j.id,
        attempt: j.attempt,
        lease_expires_at_ms: j.lease_expires_at_ms,
        run_id: j.run_id,
        episode_key: j.episode_key,
        episode: Some(episode),
        policy: Some(j.spec.endpoint_proto()),
        render: None,
    }
}

/// A render job on the wire (`Job.render`): the trace and the stored result to check against.
fn render_job(r: LeasedRender, video: &VideoConfig) -> pb::Job {
    pb::Job {
        job_id: r.id,
        attempt: r.attempt,
        lease_expires_at_ms: r.lease_expires_at_ms,
        run_id: r.run_id,
        episode_key: r.episode_key,
        episode: None,
        policy: None,
        render: Some(pb::RenderJob {
            // Fetched with FetchTrace: a lease reply is one message, a trace may be larger.
            trace_gz: Vec::new(),
            expected: r.expected.iter().map(task_proto).collect(),
            video_max_bytes: video.max_bytes,
            trace_bytes: r.trace_bytes,
            trace_sha256: r.trace_sha256,
        }),
    }
}

fn task_proto(t: &TaskOutcome) -> pb::TaskResult {
    pb::TaskResult {
        index: t.index,
        step: t.step.clone(),
        success: t.success,
        completion_time_s: t.completion_time_s,
        failure_reason: t.failure_reason.clone(),
        ..Default::default()
    }
}

#[tonic::async_trait]
impl Worker for WorkerService {
    async fn lease(&self, req: Request<pb::LeaseRequest>) -> Result<Response<pb::LeaseResponse>, Status> {
        let worker = caller(&req)?.worker()?;
        let m = req.into_inner();
        let (jobs, render) = (self.state)
            .lease_work(worker, &m.worker_id, m.max_jobs, m.wait_ms, m.max_renders > 0)
            .await?;
        let store_ok = self.state.video_dir().is_some();
        let config = self.state.config();
        let (video, live) = (&config.video, &config.live);
        let mut jobs: Vec<pb::Job> = (jobs.into_iter())
            .map(|j| {
                let test = self.state.content().is_test(&j.spec.instruction_id);
                job(j, (video, live), store_ok, test)
            })
            .collect();
        jobs.extend(render.map(|r| render_job(r, video)));
        Ok(Response::new(pb::LeaseResponse { jobs }))
    }

    async fn heartbeat(
        &self,
        req: Request<pb::HeartbeatRequest>,
    ) -> Result<Response<pb::HeartbeatResponse>, Status> {
        let worker = caller(&req)?.worker()?;
        let m = req.into_inner();
        let out = match m.render {
            true => {
                (self.state)
                    .render_heartbeat(worker, m.worker_id.trim(), m.job_id, m.attempt, m.progress)
                    .await?
            }
            false => {
                (self.state)
                    .heartbeat(worker, &m.worker_id, m.job_id, m.attempt)
                    .await?
            }
        };
        Ok(Response::new(pb::HeartbeatResponse {
            lease_expires_at_ms: out.lease_expires_at_ms.unwrap_or(0),
            cancelled: out.lease_expires_at_ms.is_none(),
        }))
    }

    async fn release(
        &self,
        req: Request<pb::ReleaseRequest>,
    ) -> Result<Response<pb::ReleaseResponse>, Status> {
        let worker = caller(&req)?.worker()?;
        let m = req.into_inner();
        let released = (self.state)
            .release(worker, &m.worker_id, m.job_id, m.attempt, &m.reason)
            .await?;
        Ok(Response::new(pb::ReleaseResponse { released }))
    }

    async fn report_result(
        &self,
        req: Request<pb::ReportResultRequest>,
    ) -> Result<Response<pb::ReportResultResponse>, Status> {
        let worker = caller(&req)?.worker()?;
        let m = req.into_inner();
        let result = m.result.unwrap_or_default();
        let tasks: Vec<TaskOutcome> = result.tasks.iter().map(TaskOutcome::from).collect();
        let path = crate::plots::from_report(result.path.as_ref(), &tasks);
        let report = Report {
            worker_id: m.worker_id,
            job_id: m.job_id,
            attempt: m.attempt,
            run_id: m.run_id,
            episode_key: m.episode_key,
            tasks,
            platform_error: result.platform_error,
            log_tail: result.log_tail,
            wall_ms: result.wall_ms,
            path,
        };
        let out = self.state.report_result(worker, report).await?;
        Ok(Response::new(pb::ReportResultResponse {
            accepted: out.accepted,
            duplicate: out.duplicate,
        }))
    }

    async fn upload_video(
        &self,
        req: Request<tonic::Streaming<pb::VideoChunk>>,
    ) -> Result<Response<pb::UploadVideoResponse>, Status> {
        caller(&req)?.worker()?;
        let (sha256, bytes) = upload::receive(&self.state, req.into_inner()).await?;
        Ok(Response::new(pb::UploadVideoResponse { sha256, bytes }))
    }

    async fn upload_trace(
        &self,
        req: Request<tonic::Streaming<pb::TraceChunk>>,
    ) -> Result<Response<pb::UploadTraceResponse>, Status> {
        caller(&req)?.worker()?;
        let (sha256, bytes) = upload::receive_trace(&self.state, req.into_inner()).await?;
        Ok(Response::new(pb::UploadTraceResponse { sha256, bytes }))
    }

    type FetchTraceStream = upload::TraceStream;

    async fn fetch_trace(
        &self,
        req: Request<pb::FetchTraceRequest>,
    ) -> Result<Response<Self::FetchTraceStream>, Status> {
        let worker = caller(&req)?.worker()?;
        let m = req.into_inner();
        let trace = (self.state)
            .render_trace(worker, m.worker_id.trim(), m.render_id, m.attempt)
            .await?;
        Ok(Response::new(upload::send_trace(trace).await?))
    }

    async fn fail_render(
        &self,
        req: Request<pb::FailRenderRequest>,
    ) -> Result<Response<pb::FailRenderResponse>, Status> {
        let worker = caller(&req)?.worker()?;
        let m = req.into_inner();
        let accepted = (self.state)
            .fail_render(worker, m.worker_id.trim(), m.render_id, m.attempt, &m.error)
            .await?;
        Ok(Response::new(pb::FailRenderResponse { accepted }))
    }
}

mod upload;

#[cfg(test)]
mod report_tests;
#[cfg(test)]
mod tests;
