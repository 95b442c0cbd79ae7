//! One gRPC connection to a policy endpoint, async: channel set-up (TLS, bearer token, size
//! caps, the checked address), the health probe, and each RPC with its deadline and its
//! failures turned into reasons a participant can act on.
//!
//! Both the sync [`RemotePolicy`](crate::RemotePolicy) and the `check-policy` probe drive it.

use std::future::Future;
use std::time::{Duration, Instant};

use kitchen_r_proto::policy::v1 as pb;
use pb::policy_client::PolicyClient;
use tonic::metadata::{Ascii, MetadataValue};
use tonic::service::Interceptor;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Uri};
use tonic::{Code, Request, Status};
use tonic_health::pb::HealthCheckRequest;
use tonic_health::pb::health_check_response::ServingStatus;
use tonic_health::pb::health_client::HealthClient;

use crate::endpoint::Endpoint;
use crate::{Credentials, RemoteConfig, RemoteError};
use kitchen_r_episode::policy::{MAX_OBSERVATION_HISTORY, PolicyError};

/// Adds `authorization: Bearer <token>` to every call when the participant gave a token.
#[derive(Debug, Clone)]
pub(crate) struct Bearer(Option<MetadataValue<Ascii>>);

impl Interceptor for Bearer {
    fn call(&mut self, mut req: Request<()>) -> Result<Request<()>, Status> {
        if let Some(v) = &self.0 {
            req.metadata_mut().insert("authorization", v.clone());
        }
        Ok(req)
    }
}

type Authed = InterceptedService<Channel, Bearer>;

/// A connection's clients; cheap to clone (one HTTP/2 connection underneath).
#[derive(Debug, Clone)]
pub(crate) struct Conn {
    pub(crate) endpoint: Endpoint,
    policy: PolicyClient<Authed>,
    health: HealthClient<Authed>,
    call_deadline: Duration,
    max_answer_bytes: usize,
}

impl Conn {
    /// A lazy channel to the first checked address of `ep`: nothing is sent until the first
    /// call, and a dropped connection is re-established by the next call.
    pub(crate) fn new(ep: Endpoint, creds: &Credentials, cfg: &RemoteConfig) -> Result<Conn, RemoteError> {
        let tls_err = |reason: String| RemoteError::Tls {
            endpoint: ep.uri.clone(),
            reason,
        };
        let scheme = if ep.tls { "https" } else { "http" };
        // Connect to the checked address, not the name: a second DNS answer cannot redirect us.
        let target = format!("{scheme}://{}", ep.addrs[0]);
        let origin: Uri = ep.uri.parse().map_err(|e| tls_err(format!("{e}")))?;
        let mut e = tonic::transport::Endpoint::from_shared(target)
            .map_err(|e| tls_err(e.to_string()))?
            .origin(origin)
            .tcp_nodelay(true)
            .connect_timeout(cfg.startup_deadline());
        if ep.tls {
            let mut tls = ClientTlsConfig::new()
                .domain_name(ep.host.clone())
                .with_webpki_roots();
            if let Some(ca) = &creds.ca_pem {
                tls = tls.ca_certificate(Certificate::from_pem(ca));
            }
            e = e.tls_config(tls).map_err(|e| tls_err(e.to_string()))?;
        }
        let bearer = match &creds.token {
            None => Bearer(None),
            Some(t) => Bearer(Some(format!("Bearer {t}").parse().map_err(|_| {
                RemoteError::Handshake {
                    endpoint: ep.uri.clone(),
                    reason: "the token must be printable ASCII".into(),
                }
            })?)),
        };
        let channel = e.connect_lazy();
        let policy = PolicyClient::with_interceptor(channel.clone(), bearer.clone())
            .max_decoding_message_size(cfg.max_answer_bytes)
            .max_encoding_message_size(cfg.max_request_bytes);
        let health = HealthClient::with_interceptor(channel, bearer).max_decoding_message_size(64 << 10);
        Ok(Conn {
            endpoint: ep,
            policy,
            health,
            call_deadline: cfg.call_deadline(),
            max_answer_bytes: cfg.max_answer_bytes,
        })
    }

    /// One health probe of the whole server (`service: ""`).
    pub(crate) async fn health(&mut self) -> Result<ServingStatus, Status> {
        let mut req = Request::new(HealthCheckRequest {
            service: String::new(),
        });
        req.set_timeout(self.call_deadline);
        let answer = within(self.call_deadline, self.health.check(req)).await?;
        Ok(ServingStatus::try_from(answer.into_inner().status).unwrap_or(ServingStatus::Unknown))
    }

    /// Probe health until SERVING or the startup deadline: a server that is still starting is
    /// given time, one that answers NOT_SERVING until the end is refused with that status.
    pub(crate) async fn wait_serving(&mut self, deadline: Duration) -> Result<(), RemoteError> {
        let started = Instant::now();
        loop {
            let (not_serving, reason) = match self.health().await {
                Ok(ServingStatus::Serving) => return Ok(()),
                Ok(s) => (true, format!("health status is {}, not SERVING", s.as_str_name())),
                Err(s) if s.code() == Code::Unimplemented => {
                    return Err(RemoteError::Health {
                        endpoint: self.endpoint.uri.clone(),
                        reason: "the server does not implement grpc.health.v1.Health".into(),
                    });
                }
                Err(s) => (false, describe("health check", &s, self.max_answer_bytes)),
            };
            if started.elapsed() >= deadline {
                let endpoint = self.endpoint.uri.clone();
                return Err(if not_serving {
                    RemoteError::Health { endpoint, reason }
                } else {
                    RemoteError::Unreachable {
                        endpoint,
                        waited_s: started.elapsed().as_secs_f64(),
                        reason,
                    }
                });
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }

    pub(crate) async fn get_spec(&mut self, cfg: &RemoteConfig) -> Result<pb::PolicySpec, RemoteError> {
        let mut req = Request::new(pb::GetSpecRequest {
            protocol_version: kitchen_r_proto::POLICY_PROTOCOL_VERSION,
            actions_executed_per_chunk: cfg.actions_executed_per_chunk,
            control_rate_hz: cfg.control_rate_hz,
            minor_version: kitchen_r_proto::POLICY_MINOR_VERSION,
            min_actions_executed_per_chunk: cfg.min_actions_executed_per_chunk,
            max_observation_history: MAX_OBSERVATION_HISTORY as u32,
            privileged_track: cfg.privileged_track,
        });
        req.set_timeout(self.call_deadline);
        within(self.call_deadline, self.policy.get_spec(req))
            .await
            .map(tonic::Response::into_inner)
            .map_err(|s| RemoteError::Handshake {
                endpoint: self.endpoint.uri.clone(),
                reason: describe("GetSpec", &s, self.max_answer_bytes),
            })
    }

    pub(crate) async fn reset(&mut self, req: pb::ResetRequest) -> Result<(), PolicyError> {
        let mut req = Request::new(req);
        req.set_timeout(self.call_deadline);
        within(self.call_deadline, self.policy.reset(req))
            .await
            .map(drop)
            .map_err(|s| self.to_policy_error("Reset", &s))
    }

    pub(crate) async fn act(&mut self, obs: pb::Observation) -> Result<pb::ActionChunk, PolicyError> {
        let mut req = Request::new(obs);
        req.set_timeout(self.call_deadline);
        within(self.call_deadline, self.policy.act(req))
            .await
            .map(tonic::Response::into_inner)
            .map_err(|s| self.to_policy_error("Act", &s))
    }

    /// This connection with size caps for ActBatch calls of up to `n` decisions: `n` times the
    /// caps of one Act (each chunk is checked against the one-Act cap when it arrives, each
    /// observation before it is handed in).
    pub(crate) fn for_batch(self, n: usize, cfg: &RemoteConfig) -> Conn {
        let n = n.max(1);
        Conn {
            policy: self
                .policy
                .max_decoding_message_size(cfg.max_answer_bytes.saturating_mul(n))
                .max_encoding_message_size(cfg.max_request_bytes.saturating_mul(n)),
            ..self
        }
    }

    /// One ActBatch call under `deadline` (the latest of its decisions' own deadlines).
    pub(crate) async fn act_batch(
        &mut self,
        batch: pb::ObservationBatch,
        deadline: Duration,
    ) -> Result<pb::ActionChunkBatch, PolicyError> {
        let mut req = Request::new(batch);
        req.set_timeout(deadline);
        within(deadline, self.policy.act_batch(req))
            .await
            .map(tonic::Response::into_inner)
            .map_err(|s| self.to_policy_error("ActBatch", &s))
    }

    pub(crate) fn max_answer_bytes(&self) -> usize {
        self.max_answer_bytes
    }

    fn to_policy_error(&self, rpc: &str, s: &Status) -> PolicyError {
        // tonic enforces the `grpc-timeout` it sends itself, as Cancelled "Timeout expired".
        let expired = s.code() == Code::Cancelled && s.message().contains("Timeout expired");
        if s.code() == Code::DeadlineExceeded || expired {
            PolicyError::Timeout(self.call_deadline.as_secs_f64())
        } else {
            PolicyError::Call(describe(rpc, s, self.max_answer_bytes))
        }
    }
}

/// `fut` under a client-side deadline: an untrusted server may ignore `grpc-timeout`.
async fn within<T>(d: Duration, fut: impl Future<Output = Result<T, Status>>) -> Result<T, Status> {
    tokio::time::timeout(d, fut)
        .await
        .unwrap_or_else(|_| Err(Status::deadline_exceeded("client-side deadline")))
}

/// A status as a reason: what happened, in words, then the code and the server's message.
pub(crate) fn describe(rpc: &str, s: &Status, max_answer_bytes: usize) -> String {
    let msg = s.message();
    let mut detail = msg.to_string();
    if let Some(src) = std::error::Error::source(s) {
        detail = format!("{detail} ({})", chain(src));
    }
    let lower = detail.to_lowercase();
    let dropped = [
        "transport",
        "connection",
        "broken pipe",
        "reset",
        "closed",
        "h2 protocol",
        "refused",
    ]
    .iter()
    .any(|w| lower.contains(w));
    let what = match s.code() {
        Code::OutOfRange if msg.contains("decoded message length too large") => {
            format!("the answer exceeds the {max_answer_bytes}-byte size cap")
        }
        Code::OutOfRange if msg.contains("encoded message length too large") => {
            "the observation exceeds the request size cap (policy.max_request_bytes)".to_string()
        }
        Code::Unavailable | Code::Unknown | Code::Internal | Code::Cancelled if dropped => {
            "the connection to the policy dropped or could not be made".to_string()
        }
        Code::Internal if lower.contains("decode") || lower.contains("protobuf") => {
            "the answer could not be decoded".to_string()
        }
        _ => "the policy answered with an error".to_string(),
    };
    format!("{rpc}: {what} (status {:?}: {detail})", s.code())
}

fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut parts = vec![e.to_string()];
    let mut cur = e.source();
    while let Some(c) = cur {
        parts.push(c.to_string());
        cur = c.source();
    }
    parts.dedup();
    parts.join(": ")
}
