//! The gRPC adapter (tonic) for `kitchen_r.submission.v1.Submissions`: converts messages and
//! calls the same service functions as the HTTP routes, so both transports apply one set of rules.
//!
//! [`GrpcStackLayer`] is the tower stack of the whole gRPC server (every service, health and
//! reflection included), the counterpart of [`crate::http::stack`]; [`CallerLayer`] under it
//! resolves each call's bearer token once, for every method of every service.

mod caller;

pub(crate) use caller::{CallerLayer, caller};

use std::any::Any;
use std::panic::AssertUnwindSafe;
use std::task::{Context, Poll};
use std::time::Duration;

use axum::http::{self, HeaderValue};
use futures_util::FutureExt;
use kitchen_r_core::dataset::Split;
use kitchen_r_core::observations::ObservationTrack;
use kitchen_r_proto::submission::v1 as pb;
use pb::submissions_server::Submissions;
use tonic::{Request, Response, Status};

use crate::config::Config;
use crate::error::{REQUEST_ID_HEADER, ServiceError, request_id_from, with_request_id};
use crate::leaderboard::intervals::{Interval, Intervals};
use crate::leaderboard::{Card, Track};
use crate::probe::BoxFuture;
use crate::service::lease::MAX_LEASE_WAIT_MS;
use crate::service::{AppState, EpisodeView, RegisterPolicy, Scores, SubmissionView};

#[derive(Debug, Clone)]
pub(crate) struct SubmissionsService {
    state: AppState,
}

impl SubmissionsService {
    pub(crate) fn new(state: AppState) -> Self {
        SubmissionsService { state }
    }

    /// The tonic server, with the decoding cap raised to the configured body limit (plus room
    /// for the envelope) so a file over the limit gets the service's own error and line.
    pub(crate) fn into_server(self) -> pb::submissions_server::SubmissionsServer<Self> {
        let cap = self.state.config().max_body_bytes.saturating_mul(2);
        pb::submissions_server::SubmissionsServer::new(self).max_decoding_message_size(cap)
    }
}

fn split(s: &str, default: Option<Split>) -> Result<Split, Status> {
    match (s, default) {
        ("", Some(d)) => Ok(d),
        _ => s.parse().map_err(|e: String| ServiceError::BadRequest(e).into()),
    }
}

fn scores(s: Scores) -> pb::Scores {
    pb::Scores {
        em: s.em,
        sr: s.sr,
        mse: s.mse,
        m: s.m,
        p: s.p,
    }
}

fn interval(i: Interval) -> pb::Interval {
    pb::Interval {
        low: i.low,
        high: i.high,
    }
}

/// A row's intervals as the HTTP board gives them (the same numbers: both adapters read the
/// service's [`Intervals`]).
fn intervals(i: Intervals) -> pb::Intervals {
    pb::Intervals {
        em: i.em.map(interval),
        sr: i.sr.map(interval),
        mse: i.mse.map(interval),
        m: i.m.map(interval),
        p: i.p.map(interval),
        sr_by_kind: (i.sr_by_kind.into_iter())
            .map(|(kind, k)| {
                let kind_sr = pb::KindSr {
                    successes: k.successes,
                    tasks: k.tasks,
                    sr: k.sr,
                    interval: Some(interval(k.interval)),
                };
                (kind, kind_sr)
            })
            .collect(),
    }
}

fn card(
    c: Card,
    label: impl Fn(Option<ObservationTrack>) -> String,
    mode: impl Fn(Option<kitchen_r_core::GraspMode>) -> String,
) -> pb::ResultsCard {
    pb::ResultsCard {
        run_id: c.run_id,
        binary_version: c.binary_version,
        config_hash: c.config_hash,
        config: c.config,
        dataset: c.dataset,
        seeds: c.seeds,
        grasp_mode: mode(c.grasp_mode),
        observations: label(c.observations),
        episodes: c.episodes,
        scorer_version: c.scorer_version,
    }
}

fn episode(e: EpisodeView) -> pb::EpisodeSummary {
    pb::EpisodeSummary {
        key: e.key,
        mode: e.mode,
        success_rate: e.success_rate,
        mse: e.mse,
        failure: e.failure.unwrap_or_default(),
        failure_reasons: e.failure_reasons,
    }
}

fn submission(v: SubmissionView) -> pb::Submission {
    pb::Submission {
        id: v.id,
        team: v.team,
        split: v.split,
        kind: v.kind,
        created_at: v.created_at,
        runs: v.runs as u32,
        ranked: v.ranked,
        unranked_reason: v.unranked_reason.unwrap_or_default(),
        latest_run: v.latest_run.map(|r| {
            let eval = r.evaluation;
            pb::ScoringRun {
                failure_counts: eval.as_ref().map_or_else(Vec::new, |e| {
                    (e.failure_counts.iter())
                        .map(|c| pb::ReasonCount {
                            reason: c.reason.clone(),
                            count: c.count as u32,
                        })
                        .collect()
                }),
                instructions_total: r.instructions_total.unwrap_or(0) as u32,
                instructions_present: r.instructions_present.unwrap_or(0) as u32,
                state: eval.as_ref().map_or_else(String::new, |e| e.state.to_string()),
                grasp_mode: eval
                    .as_ref()
                    .map_or_else(String::new, |e| e.grasp_mode.to_string()),
                episodes_total: eval.as_ref().map_or(0, |e| e.episodes_total as u32),
                episodes_done: eval.as_ref().map_or(0, |e| e.episodes_done as u32),
                episodes_running: eval.as_ref().map_or(0, |e| e.episodes_running as u32),
                episodes: eval.map_or_else(Vec::new, |e| e.episodes.into_iter().map(episode).collect()),
                id: r.id,
                scorer_version: r.scorer_version,
                created_at: r.created_at,
                scores: Some(scores(r.scores)),
                instructions: r
                    .instructions
                    .into_iter()
                    .map(|i| pb::InstructionResult {
                        id: i.id,
                        present: i.present,
                        correct_steps: i.correct_steps as u32,
                        total_steps: i.total_steps as u32,
                        em: i.em,
                    })
                    .collect(),
            }
        }),
    }
}

#[tonic::async_trait]
impl Submissions for SubmissionsService {
    async fn submit_plans(
        &self,
        req: Request<pb::SubmitPlansRequest>,
    ) -> Result<Response<pb::SubmitPlansResponse>, Status> {
        let caller = caller(&req)?;
        let team = caller.team()?;
        let msg = req.into_inner();
        let split = split(&msg.split, None)?;
        let done = self.state.submit_plans(team, split, &msg.body).await?;
        Ok(Response::new(pb::SubmitPlansResponse {
            id: done.id,
            scores: Some(scores(done.scores)),
            warnings: done.warnings,
        }))
    }

    async fn register_policy(
        &self,
        req: Request<pb::RegisterPolicyRequest>,
    ) -> Result<Response<pb::RegisterPolicyResponse>, Status> {
        let caller = caller(&req)?;
        let m = req.into_inner();
        let request = RegisterPolicy {
            endpoint: m.endpoint,
            split: split(&m.split, None)?,
            token: Some(m.endpoint_token).filter(|t| !t.is_empty()),
            plans: (m.plans_submission_id != 0).then_some(m.plans_submission_id),
            episodes: m.episodes,
            reference: m.reference,
            key_map: crate::service::policies::key_map_from_text(&m.key_map)?,
        };
        let done = self.state.register_policy(&caller, request).await?;
        Ok(Response::new(pb::RegisterPolicyResponse {
            id: done.id,
            episodes: done.episodes as u32,
            run_id: done.run_id,
            instructions: done.instructions as u32,
            max_concurrency: done.max_concurrency,
            policy: done.policy,
            observations: done.observations.to_string(),
        }))
    }

    async fn get_submission(
        &self,
        req: Request<pb::GetSubmissionRequest>,
    ) -> Result<Response<pb::Submission>, Status> {
        let caller = caller(&req)?;
        let view = self.state.get_submission(&caller, req.into_inner().id).await?;
        Ok(Response::new(submission(view)))
    }

    async fn get_leaderboard(
        &self,
        req: Request<pb::GetLeaderboardRequest>,
    ) -> Result<Response<pb::Leaderboard>, Status> {
        let msg = req.into_inner();
        let track: Track = msg.track.parse()?;
        let split = split(&msg.split, Some(Split::Test))?;
        let observations: ObservationTrack =
            (msg.observations.parse()).map_err(|e: String| Status::invalid_argument(e))?;
        let grasp = match msg.grasp_mode.as_str() {
            "" => None,
            m => Some(m.parse().map_err(|e: String| Status::invalid_argument(e))?),
        };
        let board = self.state.board(track, observations, grasp, split).await?;
        let label = |o: Option<ObservationTrack>| o.map_or_else(String::new, |o| o.to_string());
        let mode = |g: Option<kitchen_r_core::GraspMode>| g.map_or_else(String::new, |g| g.to_string());
        Ok(Response::new(pb::Leaderboard {
            track: track.as_str().into(),
            split: split.to_string(),
            observations: label(board.observations),
            grasp_mode: mode(board.grasp_mode),
            interval_ties: board.interval_ties,
            ties: board.ties.into(),
            rows: board
                .rows
                .into_iter()
                .map(|r| pb::LeaderboardRow {
                    rank: r.rank.map_or(0, |n| n as u32),
                    team: r.team,
                    submission_id: r.submission_id,
                    scores: Some(scores(r.scores)),
                    submitted_at: r.submitted_at,
                    baseline: r.baseline,
                    observations: label(r.observations),
                    grasp_mode: mode(r.grasp_mode),
                    intervals: Some(intervals(r.intervals)),
                    card: r.card.map(|c| card(c, label, mode)),
                    state: r.state.unwrap_or_default(),
                })
                .collect(),
        }))
    }
}

/// The tower stack around every gRPC call, in one layer: metrics (calls and latency by method
/// path and grpc-status, see [`crate::metrics::record_grpc`]), the request id (the caller's
/// `x-request-id` metadata when sane, else a fresh one; current while the call runs, so
/// `INTERNAL` and `UNAVAILABLE` messages name it, and echoed as `x-request-id` response
/// metadata), a trace span with the gRPC path and the id, a budget (past it `UNAVAILABLE`, code
/// `timeout`) and catch-panic (a handler that panics answers `INTERNAL` with the id; the panic
/// message is logged, never sent).
///
/// Not tonic's own `Server::timeout`: it has one budget for every call, which would either cut
/// a worker's long-polling `Lease` (up to [`MAX_LEASE_WAIT_MS`]) and a `RegisterPolicy` that
/// probes the endpoint, or be far too long for everything else. Not tower-http's catch-panic
/// either: its answer is an HTTP 500, which a gRPC client reads as a transport failure rather
/// than a status. The budget covers the call up to its response headers (streamed bodies, as in
/// reflection or health `Watch`, are not cut).
#[derive(Debug, Clone)]
pub(crate) struct GrpcStackLayer {
    default: Duration,
    registration: Duration,
    lease: Duration,
}

impl GrpcStackLayer {
    pub(crate) fn new(cfg: &Config) -> Self {
        GrpcStackLayer {
            default: cfg.request_timeout(),
            registration: cfg.registration_timeout(),
            lease: cfg.request_timeout() + Duration::from_millis(MAX_LEASE_WAIT_MS.into()),
        }
    }

    /// The budget of the call at `path` (`/package.Service/Method`).
    fn budget(&self, path: &str) -> Duration {
        let (service, method) = path.trim_start_matches('/').split_once('/').unwrap_or_default();
        match (service, method) {
            (kitchen_r_proto::worker::v1::worker_server::SERVICE_NAME, "Lease") => self.lease,
            (pb::submissions_server::SERVICE_NAME, "RegisterPolicy") => self.registration,
            _ => self.default,
        }
    }
}

impl<S> tower::Layer<S> for GrpcStackLayer {
    type Service = GrpcStack<S>;

    fn layer(&self, inner: S) -> GrpcStack<S> {
        GrpcStack {
            inner,
            layer: self.clone(),
        }
    }
}

/// The service [`GrpcStackLayer`] wraps around the gRPC routes.
#[derive(Debug, Clone)]
pub(crate) struct GrpcStack<S> {
    inner: S,
    layer: GrpcStackLayer,
}

impl<S, ReqBody, ResBody> tower::Service<http::Request<ReqBody>> for GrpcStack<S>
where
    S: tower::Service<http::Request<ReqBody>, Response = http::Response<ResBody>>,
    S::Future: Send + 'static,
    S::Error: Send + 'static,
    ResBody: Default + Send + 'static,
{
    type Response = http::Response<ResBody>;
    type Error = S::Error;
    type Future = BoxFuture<'static, Result<Self::Response, Self::Error>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, req: http::Request<ReqBody>) -> Self::Future {
        use tracing::Instrument;
        let id = request_id_from(req.headers());
        let path = req.uri().path().to_owned();
        let budget = self.layer.budget(&path);
        let span = tracing::info_span!("grpc", path = %path, request_id = %id);
        let started = std::time::Instant::now();
        // The future is never polled again after a panic, so no broken state is observed.
        let call = AssertUnwindSafe(self.inner.call(req)).catch_unwind();
        let answer = async move {
            let result = match tokio::time::timeout(budget, call).await {
                Ok(Ok(done)) => done,
                Ok(Err(panic)) => Ok(status_response(panic_error(&*panic))),
                Err(_) => Ok(status_response(ServiceError::Timeout {
                    after_ms: u64::try_from(budget.as_millis()).unwrap_or(u64::MAX),
                })),
            };
            result.map(|mut resp| {
                crate::metrics::record_grpc(&path, resp.headers(), started.elapsed());
                if let Some(id) = crate::error::current_request_id()
                    && let Ok(v) = HeaderValue::from_str(&id)
                {
                    resp.headers_mut().insert(REQUEST_ID_HEADER, v);
                }
                resp
            })
        };
        Box::pin(with_request_id(id, answer).instrument(span))
    }
}

/// A trailers-only gRPC answer for `e` (built inside the request id's scope).
fn status_response<B: Default>(e: ServiceError) -> http::Response<B> {
    Status::from(e).into_http()
}

fn panic_error(panic: &(dyn Any + Send)) -> ServiceError {
    let what = panic
        .downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a non-string payload".into());
    ServiceError::Internal(anyhow::anyhow!("handler panicked: {what}"))
}

#[cfg(test)]
mod stack_tests {
    use std::convert::Infallible;

    use tower::{Layer, ServiceExt};

    use super::*;

    type Reply = Result<http::Response<tonic::body::Body>, Infallible>;

    fn stack<F, Fut>(
        cfg: &Config,
        f: F,
    ) -> impl tower::Service<
        http::Request<()>,
        Response = http::Response<tonic::body::Body>,
        Error = Infallible,
    > + use<F, Fut>
    where
        F: FnMut(http::Request<()>) -> Fut,
        Fut: Future<Output = Reply> + Send + 'static,
    {
        GrpcStackLayer::new(cfg).layer(tower::service_fn(f))
    }

    fn call_to(path: &str, id: Option<&str>) -> http::Request<()> {
        let mut req = http::Request::post(path);
        if let Some(id) = id {
            req = req.header(REQUEST_ID_HEADER, id);
        }
        req.body(()).unwrap()
    }

    fn grpc_status(resp: &http::Response<tonic::body::Body>) -> (Option<&str>, String) {
        let status = Status::from_header_map(resp.headers()).expect("a trailers-only status");
        (
            resp.headers()
                .get(REQUEST_ID_HEADER)
                .and_then(|v| v.to_str().ok()),
            format!("{:?}: {}", status.code(), status.message()),
        )
    }

    #[tokio::test]
    async fn a_panicking_call_is_internal_with_the_request_id_and_no_internals() {
        let svc = stack(&Config::default(), |_| async { panic!("secret internals") });
        let resp = svc
            .oneshot(call_to(
                "/kitchen_r.submission.v1.Submissions/GetSubmission",
                Some("req-7"),
            ))
            .await
            .unwrap();
        let (id, status) = grpc_status(&resp);
        assert_eq!(id, Some("req-7"));
        assert_eq!(status, "Internal: internal error (request id req-7)");
    }

    /// On tokio's paused clock: the budgets and the slow handler are timers, nothing real is
    /// waited for (the stack is called in process, no socket, no database).
    #[tokio::test(start_paused = true)]
    async fn a_call_past_its_budget_is_unavailable_but_a_long_poll_lease_is_not_cut() {
        let cfg = Config {
            request_timeout_ms: 100,
            ..Config::default()
        };
        let slow = |_| async {
            // Past the 100 ms budget, well within a Lease's (100 ms + 30 s).
            tokio::time::sleep(Duration::from_millis(400)).await;
            Ok(Status::ok("").into_http())
        };
        let resp = stack(&cfg, slow)
            .oneshot(call_to(
                "/kitchen_r.submission.v1.Submissions/GetLeaderboard",
                None,
            ))
            .await
            .unwrap();
        let (id, status) = grpc_status(&resp);
        assert_eq!(id.map(str::len), Some(16), "a generated id: {id:?}");
        assert!(
            status.starts_with("Unavailable: the request took longer than 100 ms"),
            "{status}"
        );
        let resp = stack(&cfg, slow)
            .oneshot(call_to("/kitchen_r.worker.v1.Worker/Lease", None))
            .await
            .unwrap();
        assert_eq!(grpc_status(&resp).1, "Ok: ");
    }

    /// Through the real server and a real client: errors carry the caller's id as metadata.
    #[tokio::test]
    async fn grpc_errors_carry_the_request_id_metadata() {
        use crate::testutil::{FakeProbe, fixture};
        let f = fixture(FakeProbe::ok(1), |_| {}).await;
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let routes = crate::grpc_routes(f.state.clone()).await.unwrap();
        tokio::spawn(routes.serve_with_incoming(tokio_stream::wrappers::TcpListenerStream::new(listener)));
        let mut client = pb::submissions_client::SubmissionsClient::connect(format!("http://{addr}"))
            .await
            .unwrap();
        let mut req = Request::new(pb::GetSubmissionRequest { id: 1 });
        req.metadata_mut()
            .insert(REQUEST_ID_HEADER, "grpc-req-9".parse().unwrap());
        let e = client.get_submission(req).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::Unauthenticated);
        assert_eq!(
            e.metadata().get(REQUEST_ID_HEADER).map(|v| v.to_str().unwrap()),
            Some("grpc-req-9")
        );
    }
}
