//! The registration probe: before a policy endpoint is accepted, something must check that its
//! address is allowed, that it reports SERVING on `grpc.health.v1` and that `GetSpec` answers a
//! protocol this server speaks.
//!
//! The server crate only defines the seam ([`PolicyProbe`]): talking to a policy is the worker
//! crate's job (`kitchen_r_contract`), and the server must not depend on the simulator.
//! The `kitchen-r` binary passes the real probe to [`crate::build_with`]; [`crate::build`]
//! installs [`NoProbe`], which refuses every registration with a clear 503, so a server that
//! cannot evaluate policies never queues work no one will do.

use std::future::Future;
use std::pin::Pin;

/// A boxed, sendable future (what [`PolicyProbe::probe`] returns).
pub type BoxFuture<'a, T> = Pin<Box<dyn Future<Output = T> + Send + 'a>>;

/// What the probe learnt from a healthy endpoint's `GetSpec`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProbedSpec {
    /// Protocol version the policy speaks; must be [`kitchen_r_proto::POLICY_PROTOCOL_VERSION`].
    pub protocol_version: u32,
    /// Concurrent `Act` calls the policy serves; 0 is read as 1 (policy.proto).
    pub max_concurrency: u32,
    /// One line for the submission page and logs (name, cameras, encoding).
    pub summary: String,
    /// Contract v1.1 choices as announced (0 = not set): frames per Act, actions executed per
    /// chunk. The server checks them against its `[control]` ranges.
    pub observation_history: u32,
    pub actions_executed_per_chunk: u32,
    /// The policy asks for privileged observations (the privileged track); the server refuses
    /// it unless `control.privileged_track` is on.
    pub privileged_observations: bool,
    /// An openpi (`ws://`) endpoint's key map as the probe checked it, every field spelt out
    /// (JSON): stored with the endpoint and handed to the workers. `None` for gRPC.
    pub key_map: Option<String>,
}

/// Why an endpoint was not accepted. Messages are shown to the participant as they are.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProbeError {
    /// The address itself is refused (malformed, private network not allowed, ...).
    #[error("{0}")]
    Refused(String),
    /// The endpoint was reached (or not) but did not behave: not SERVING, GetSpec failed or
    /// announced something unsupported, startup deadline passed.
    #[error("{0}")]
    Failed(String),
    /// This server cannot probe at all (built without a probe).
    #[error("{0}")]
    Unavailable(String),
}

/// Checks a participant's endpoint at registration. `bearer` is the token the evaluator will
/// send to the endpoint; `key_map` an openpi endpoint's key map as the participant gave it
/// (JSON). Implementations own the address allow-list (config `policy.allow_networks`), the
/// deadlines and the transports.
pub trait PolicyProbe: Send + Sync + 'static {
    fn probe(
        &self,
        url: &str,
        bearer: Option<&str>,
        key_map: Option<&str>,
    ) -> BoxFuture<'static, Result<ProbedSpec, ProbeError>>;
}

/// The probe of a server built without policy evaluation: refuses every registration.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProbe;

impl PolicyProbe for NoProbe {
    fn probe(
        &self,
        _url: &str,
        _bearer: Option<&str>,
        _key_map: Option<&str>,
    ) -> BoxFuture<'static, Result<ProbedSpec, ProbeError>> {
        Box::pin(async {
            Err(ProbeError::Unavailable(
                "this server was started without policy evaluation: policy registration is disabled".into(),
            ))
        })
    }
}

impl From<ProbeError> for crate::error::ServiceError {
    fn from(e: ProbeError) -> Self {
        use crate::error::ServiceError;
        match e {
            ProbeError::Refused(m) => ServiceError::EndpointRefused(m),
            ProbeError::Failed(m) => ServiceError::ProbeFailed(m),
            ProbeError::Unavailable(m) => ServiceError::PolicyDisabled(m),
        }
    }
}
