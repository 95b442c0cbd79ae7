//! Any in-process [`Policy`] served over the participant contract (`kitchen_r.policy.v1.Policy`
//! plus `grpc.health.v1`): the organisers' oracle behind `kitchen-r policy oracle`, and in tests
//! deliberately misbehaving policies, so the worker is tested against the real wire.
//!
//! Policies are stateful per episode (the oracle keeps its controller between Act calls), so
//! the server keeps one policy instance per `episode_id`, created by the factory at the first
//! Reset of that episode; the least recently used instances are dropped past a bound.

use std::collections::HashMap;
use std::future::Future;
use std::sync::{Arc, Mutex};

use kitchen_r_proto::POLICY_PROTOCOL_VERSION;
use kitchen_r_proto::policy::v1 as pb;
use pb::policy_server::{Policy as PolicyRpc, PolicyServer};
use tokio_stream::StreamExt;
use tokio_stream::wrappers::TcpListenerStream;
use tonic::{Request, Response, Status};

use crate::convert;
use kitchen_r_episode::policy::{Policy, PolicyError, PolicyInput};

/// Makes one policy instance per episode.
pub type PolicyFactory = Arc<dyn Fn() -> Box<dyn Policy> + Send + Sync>;

/// How a policy is served.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// Cameras announced in GetSpec; empty = the contract's defaults (`base`, `gripper`,
    /// 128×128 RAW_RGB8).
    pub cameras: Vec<pb::CameraRequest>,
    /// Largest observation accepted, bytes.
    pub max_request_bytes: usize,
    /// Episodes whose policy instance is kept.
    pub max_episodes: usize,
    /// Serve over TLS with this certificate chain and private key (PEM); plain gRPC when unset.
    pub tls: Option<TlsIdentity>,
    /// GetSpec's `max_batch`: the most decisions one ActBatch call may carry; 0 or 1 = the
    /// workers send Acts only (ActBatch is answered either way).
    pub max_batch: u32,
}

/// A server certificate chain and its private key, PEM-encoded.
#[derive(Debug, Clone)]
pub struct TlsIdentity {
    pub cert_pem: Vec<u8>,
    pub key_pem: Vec<u8>,
}

impl Default for ServeOptions {
    fn default() -> Self {
        ServeOptions {
            cameras: Vec::new(),
            max_request_bytes: 64 << 20,
            max_episodes: 256,
            tls: None,
            max_batch: 0,
        }
    }
}

type Shared = Arc<Mutex<Box<dyn Policy>>>;

#[derive(Default)]
struct Episodes {
    clock: u64,
    by_id: HashMap<String, (u64, Shared)>,
}

struct Service {
    factory: PolicyFactory,
    spec: pb::PolicySpec,
    episodes: Mutex<Episodes>,
    max_episodes: usize,
}

impl Service {
    /// The episode's policy, created when `create` and unknown.
    fn episode(&self, id: &str, create: bool) -> Result<Shared, Status> {
        let mut e = self
            .episodes
            .lock()
            .map_err(|_| Status::internal("policy state poisoned"))?;
        e.clock += 1;
        let now = e.clock;
        if let Some((used, p)) = e.by_id.get_mut(id) {
            *used = now;
            return Ok(p.clone());
        }
        if !create {
            return Err(Status::failed_precondition(format!(
                "Act for episode {id:?} before any Reset of that episode"
            )));
        }
        if e.by_id.len() >= self.max_episodes
            && let Some(oldest) = e
                .by_id
                .iter()
                .min_by_key(|(_, (u, _))| *u)
                .map(|(k, _)| k.clone())
        {
            e.by_id.remove(&oldest);
        }
        let p: Shared = Arc::new(Mutex::new((self.factory)()));
        e.by_id.insert(id.to_string(), (now, p.clone()));
        Ok(p)
    }
}

fn status(e: PolicyError) -> Status {
    match e {
        PolicyError::NeedsPrivileged => Status::failed_precondition(
            "this is a reference policy: it needs the privileged world state \
             (Observation.privileged), which only organiser reference runs send",
        ),
        other => Status::internal(other.to_string()),
    }
}

/// Run a sync policy call off the async threads: policies may plan for milliseconds.
async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, Status> + Send + 'static,
) -> Result<T, Status> {
    tokio::task::spawn_blocking(f)
        .await
        .unwrap_or_else(|e| Err(Status::internal(format!("policy panicked: {e}"))))
}

#[tonic::async_trait]
impl PolicyRpc for Service {
    async fn get_spec(&self, _: Request<pb::GetSpecRequest>) -> Result<Response<pb::PolicySpec>, Status> {
        Ok(Response::new(self.spec.clone()))
    }

    async fn reset(&self, req: Request<pb::ResetRequest>) -> Result<Response<pb::ResetResponse>, Status> {
        let r = req.into_inner();
        let p = self.episode(&r.episode_id, true)?;
        blocking(move || {
            let mut p = p.lock().map_err(|_| Status::internal("policy state poisoned"))?;
            p.reset(&r.episode_id, r.task_index as usize, &r.sub_task)
                .map_err(status)
        })
        .await?;
        Ok(Response::new(pb::ResetResponse {}))
    }

    async fn act(&self, req: Request<pb::Observation>) -> Result<Response<pb::ActionChunk>, Status> {
        let o = req.into_inner();
        let p = self.episode(&o.episode_id, false)?;
        let chunk = blocking(move || act_one(&p, &o)).await?;
        Ok(Response::new(chunk))
    }

    /// Each observation answered by its own episode's policy, exactly as its Act would be: a
    /// batch changes no answer. One failing decision fails the call (as one failing Act fails
    /// that Act), so the worker fails each of the batch's decisions with the reason.
    async fn act_batch(
        &self,
        req: Request<pb::ObservationBatch>,
    ) -> Result<Response<pb::ActionChunkBatch>, Status> {
        let batch = req.into_inner().observations;
        let most = self.spec.max_batch.max(1) as usize;
        if batch.len() > most {
            return Err(Status::invalid_argument(format!(
                "ActBatch carries {} observations, more than this policy's max_batch {most}",
                batch.len()
            )));
        }
        let policies = (batch.iter())
            .map(|o| self.episode(&o.episode_id, false))
            .collect::<Result<Vec<_>, _>>()?;
        let chunks = blocking(move || {
            (policies.iter().zip(&batch))
                .map(|(p, o)| act_one(p, o))
                .collect::<Result<Vec<_>, _>>()
        })
        .await?;
        Ok(Response::new(pb::ActionChunkBatch { chunks }))
    }
}

/// One decision of the episode's policy `p`, from the wire and back.
fn act_one(p: &Shared, o: &pb::Observation) -> Result<pb::ActionChunk, Status> {
    let obs = convert::observation_from_wire(o).map_err(Status::invalid_argument)?;
    let privileged = match &o.privileged {
        Some(pv) => Some(convert::privileged_from_wire(pv).map_err(Status::invalid_argument)?),
        None => None,
    };
    let shown = match &o.privileged_observation {
        Some(pv) => Some(convert::privileged::from_wire(pv).map_err(Status::invalid_argument)?),
        None => None,
    };
    let history = (o.history.iter())
        .map(convert::frame_from_wire)
        .collect::<Result<Vec<_>, _>>()
        .map_err(Status::invalid_argument)?;
    let robot = o.robot.clone().unwrap_or_default();
    let input = PolicyInput {
        episode_id: &o.episode_id,
        step: o.step,
        task_index: o.task_index as usize,
        sub_task: &o.sub_task,
        observation: &obs,
        ee_pose: convert::ee_pose_from_wire(&robot.ee_pose).map_err(Status::invalid_argument)?,
        previous_action: convert::action_from_wire(&o.previous_action).map_err(Status::invalid_argument)?,
        history: &history,
        privileged: privileged.as_ref(),
        privileged_observation: shown.as_ref(),
    };
    let mut p = p.lock().map_err(|_| Status::internal("policy state poisoned"))?;
    p.act(&input).map(|c| convert::chunk_to_wire(&c)).map_err(status)
}

/// Serve `factory`'s policies on `listener` until `shutdown` resolves.
pub async fn serve_policy(
    listener: tokio::net::TcpListener,
    factory: PolicyFactory,
    opts: ServeOptions,
    shutdown: impl Future<Output = ()> + Send,
) -> Result<(), tonic::transport::Error> {
    let s = factory().spec().clone();
    let cameras = if opts.cameras.is_empty() && !s.cameras.is_empty() {
        s.cameras
            .iter()
            .map(|n| pb::CameraRequest {
                name: n.clone(),
                width: 128,
                height: 128,
                encoding: pb::ImageEncoding::RawRgb8 as i32,
                depth: false,
            })
            .collect()
    } else {
        opts.cameras.clone()
    };
    let spec = pb::PolicySpec {
        protocol_version: POLICY_PROTOCOL_VERSION,
        cameras,
        horizon: s.horizon as u32,
        action_dim: s.action_dim as u32,
        max_concurrency: s.max_concurrency,
        name: s.name,
        // A v1 policy (history 1, organiser's count) announces neither, as a v1 server would.
        observation_history: if s.observation_history > 1 {
            s.observation_history as u32
        } else {
            0
        },
        actions_executed_per_chunk: s.actions_executed_per_chunk.map_or(0, |n| n as u32),
        privileged_observations: s.privileged_observations,
        max_batch: opts.max_batch,
    };
    let service = Service {
        factory,
        spec,
        episodes: Mutex::new(Episodes::default()),
        max_episodes: opts.max_episodes.max(1),
    };
    let (reporter, health) = tonic_health::server::health_reporter();
    reporter.set_serving::<PolicyServer<Service>>().await;
    // Small answers must not wait for Nagle's algorithm: it costs ~40 ms per call on loopback.
    let incoming = TcpListenerStream::new(listener).map(|s| {
        if let Ok(s) = &s {
            let _ = s.set_nodelay(true);
        }
        s
    });
    let mut builder = tonic::transport::Server::builder();
    if let Some(id) = &opts.tls {
        let identity = tonic::transport::Identity::from_pem(&id.cert_pem, &id.key_pem);
        builder = builder.tls_config(tonic::transport::ServerTlsConfig::new().identity(identity))?;
    }
    builder
        .add_service(health)
        .add_service(
            PolicyServer::new(service)
                .max_decoding_message_size(opts.max_request_bytes)
                .max_encoding_message_size(usize::MAX),
        )
        .serve_with_incoming_shutdown(incoming, shutdown)
        .await
}
