//! The registration probe: before the server accepts a policy endpoint (and queues episodes
//! for it), it checks what a worker will need: an allowed address, `grpc.health.v1` SERVING
//! within the startup deadline, and a GetSpec answer this worker can drive; for an openpi
//! endpoint (`ws://`), a usable key map, `/healthz` answering 200 and the metadata sent on
//! connect. Each refusal says
//! exactly what failed, because the participant sees it as the reason of a 4xx.
//!
//! Async and short (no Act call: that is `check-policy`'s job), so the server awaits it inside
//! the registration request.

use std::net::IpAddr;
use std::time::Instant;

use kitchen_r_proto::policy::v1 as pb;
use kitchen_r_sim::SensorsConfig;

use crate::conn::Conn;
use crate::endpoint::{self, EndpointError, Transport, class_range};
use crate::{AllowedNetworks, Credentials, RemoteConfig, RemoteError, SimCamera, client, openpi};

/// What the endpoint announced, accepted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ProbedSpec {
    /// The endpoint as checked, `scheme://host:port`.
    pub endpoint: String,
    pub protocol_version: u32,
    /// Parallel episodes the endpoint accepts (at least 1); the queue honours it.
    pub max_concurrency: u32,
    /// The policy's self-declared name.
    pub name: String,
    /// Contract v1.1 choices as announced (0 = not set), already checked against the ranges
    /// of the probe's [`RemoteConfig`]: frames per Act and actions executed per chunk.
    pub observation_history: u32,
    pub actions_executed_per_chunk: u32,
    /// The policy asks for privileged observations (the privileged track). The probe does not
    /// judge it: the server refuses it, naming its config key, when the track is off.
    pub privileged_observations: bool,
    /// One line for the participant: name, version, shape, cameras, concurrency.
    pub summary: String,
    /// An openpi endpoint's key map, checked and spelt out in full (JSON): what the workers use.
    /// `None` for gRPC.
    pub key_map: Option<String>,
}

/// Why an endpoint was refused at registration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProbeFailure {
    #[error("{0}")]
    Malformed(String),
    #[error("{0}")]
    Resolve(String),
    #[error(
        "policy endpoint {endpoint} resolves to {addr}, a {kind} address, which this server \
         refuses; an organiser allows it by adding {range} to `policy.allow_networks` in the \
         server config"
    )]
    Refused {
        endpoint: String,
        addr: IpAddr,
        kind: String,
        range: String,
    },
    #[error("{0}")]
    Unreachable(String),
    #[error("{0}")]
    NotServing(String),
    #[error("{0}")]
    Handshake(String),
    #[error("{0}")]
    Tls(String),
    #[error("the probe could not run: {0}")]
    Internal(String),
}

impl From<EndpointError> for ProbeFailure {
    fn from(e: EndpointError) -> Self {
        match e {
            EndpointError::Malformed { .. } => ProbeFailure::Malformed(e.to_string()),
            EndpointError::Resolve { .. } => ProbeFailure::Resolve(e.to_string()),
            EndpointError::Refused {
                endpoint, addr, kind, ..
            } => ProbeFailure::Refused {
                endpoint,
                addr,
                kind: kind.to_string(),
                range: class_range(addr).map_or_else(|| "its range".to_string(), |r| format!("\"{r}\"")),
            },
        }
    }
}

impl From<RemoteError> for ProbeFailure {
    fn from(e: RemoteError) -> Self {
        let text = e.to_string();
        match e {
            RemoteError::Endpoint(e) => e.into(),
            RemoteError::Unreachable { .. } => ProbeFailure::Unreachable(text),
            RemoteError::Health { .. } => ProbeFailure::NotServing(text),
            RemoteError::Handshake { .. } => ProbeFailure::Handshake(text),
            RemoteError::Tls { .. } => ProbeFailure::Tls(text),
            RemoteError::Runtime(_) => ProbeFailure::Internal(text),
        }
    }
}

/// The cameras the simulator can render, which a policy's GetSpec may ask for.
fn sim_cameras() -> Result<Vec<SimCamera>, ProbeFailure> {
    SensorsConfig::load_default()
        .map(|s| SimCamera::from_sensors(&s))
        .map_err(|e| ProbeFailure::Internal(format!("simulator cameras: {e}")))
}

/// Probe `url` as a worker would call it: allow-list (`allow`), health SERVING within
/// `cfg.startup_deadline_s`, GetSpec (protocol version, horizon 16, action dim 10, cameras the
/// simulator has); for `ws://` the key map (`key_map`, JSON, empty for the convention), health
/// and metadata. `cfg.allowed_networks` is ignored in favour of `allow`.
pub async fn probe_endpoint(
    url: &str,
    bearer: Option<&str>,
    key_map: &str,
    allow: &AllowedNetworks,
    cfg: &RemoteConfig,
) -> Result<ProbedSpec, ProbeFailure> {
    probe_with_cameras(url, bearer, key_map, allow, cfg, &sim_cameras()?, false).await
}

/// [`probe_endpoint`] as the server's registration runs it, where the caller is a participant
/// and the prober is the evaluation host. An endpoint on a non-public address (loopback,
/// private, link-local, when the organiser's config allows them) is on or near that host, so a
/// failure to reach or use it says only "unreachable", after the full startup deadline: neither
/// the text nor the time tells a closed port from an HTTP or another gRPC service there. A
/// public endpoint keeps the detailed reason (it is the participant's own server).
pub async fn probe_for_registration(
    url: &str,
    bearer: Option<&str>,
    key_map: &str,
    allow: &AllowedNetworks,
    cfg: &RemoteConfig,
) -> Result<ProbedSpec, ProbeFailure> {
    probe_with_cameras(url, bearer, key_map, allow, cfg, &sim_cameras()?, true).await
}

/// [`probe_endpoint`] against an explicit camera set.
async fn probe_with_cameras(
    url: &str,
    bearer: Option<&str>,
    key_map: &str,
    allow: &AllowedNetworks,
    cfg: &RemoteConfig,
    cameras: &[SimCamera],
    opaque_near: bool,
) -> Result<ProbedSpec, ProbeFailure> {
    let started = Instant::now();
    let (owned_url, allow_copy) = (url.to_string(), *allow);
    // Name resolution blocks: keep it off the server's async threads.
    let ep = tokio::task::spawn_blocking(move || endpoint::resolve(&owned_url, &allow_copy))
        .await
        .map_err(|e| ProbeFailure::Internal(e.to_string()))??;
    let near = ep.addrs.iter().any(|a| endpoint::classify(a.ip()).is_some());
    let uri = ep.uri.clone();
    let answer = match ep.transport {
        Transport::Openpi => openpi_handshake(ep, bearer, key_map, cfg, cameras).await,
        Transport::Grpc if !key_map.trim().is_empty() => Err(ProbeFailure::Handshake(format!(
            "{uri}: a key map applies to ws:// and wss:// (openpi) endpoints only"
        ))),
        Transport::Grpc => handshake(ep, bearer, cfg, cameras).await,
    };
    match answer {
        Err(
            ProbeFailure::Unreachable(_)
            | ProbeFailure::NotServing(_)
            | ProbeFailure::Handshake(_)
            | ProbeFailure::Tls(_),
        ) if opaque_near && near => {
            tokio::time::sleep_until((started + cfg.startup_deadline()).into()).await;
            Err(ProbeFailure::Unreachable(format!(
                "cannot reach a policy at {uri} within {:.0} s",
                cfg.startup_deadline().as_secs_f64()
            )))
        }
        other => other,
    }
}

fn bearer_creds(bearer: Option<&str>) -> Credentials {
    Credentials {
        token: bearer.filter(|t| !t.is_empty()).map(str::to_string),
        ca_pem: None,
    }
}

/// An openpi endpoint: the key map checked, `/healthz` 200, metadata on connect.
async fn openpi_handshake(
    ep: endpoint::Endpoint,
    bearer: Option<&str>,
    key_map: &str,
    cfg: &RemoteConfig,
    cameras: &[SimCamera],
) -> Result<ProbedSpec, ProbeFailure> {
    let h = openpi::handshake(ep, &bearer_creds(bearer), cfg, cameras, key_map).await?;
    let keys = h.keys().clone();
    let spec = ProbedSpec {
        endpoint: h.uri().to_string(),
        // The worker speaks the contract for it: the adapter's version is ours.
        protocol_version: kitchen_r_proto::POLICY_PROTOCOL_VERSION,
        max_concurrency: keys.max_concurrency,
        name: format!("openpi {}", h.uri()),
        observation_history: 1,
        actions_executed_per_chunk: keys.actions_executed_per_chunk.unwrap_or(0),
        privileged_observations: false,
        summary: h.summary(cfg),
        key_map: Some(keys.to_json()),
    };
    h.close().await;
    Ok(spec)
}

/// Health until SERVING, then GetSpec, checked against what the simulator can give.
async fn handshake(
    ep: endpoint::Endpoint,
    bearer: Option<&str>,
    cfg: &RemoteConfig,
    cameras: &[SimCamera],
) -> Result<ProbedSpec, ProbeFailure> {
    let creds = bearer_creds(bearer);
    let mut conn = Conn::new(ep, &creds, cfg)?;
    conn.wait_serving(cfg.startup_deadline()).await?;
    let spec = conn.get_spec(cfg).await?;
    let (checked, plans) = client::check_spec(&spec, cameras, cfg).map_err(|reason| {
        ProbeFailure::Handshake(format!("GetSpec answer of {}: {reason}", conn.endpoint.uri))
    })?;
    let cams: Vec<String> = plans
        .iter()
        .map(|p| {
            let enc = if p.encoding == pb::ImageEncoding::Jpeg {
                "jpeg"
            } else {
                "raw"
            };
            format!(
                "{} {}x{} {enc}{}",
                p.name,
                p.width,
                p.height,
                if p.depth { "+depth" } else { "" }
            )
        })
        .collect();
    let execute = checked
        .actions_executed_per_chunk
        .map_or_else(|| "default".to_string(), |n| n.to_string());
    let summary = format!(
        "{:?} at {}: protocol v{}, horizon {}, action dim {}, cameras [{}], max concurrency {}, \
         history {}, executes {execute}{}{}",
        spec.name,
        conn.endpoint.uri,
        spec.protocol_version,
        checked.horizon,
        checked.action_dim,
        cams.join(", "),
        checked.max_concurrency,
        checked.observation_history,
        // Standard summaries read as before the privileged track existed.
        if spec.privileged_observations {
            ", privileged observations"
        } else {
            ""
        },
        // Likewise for policies that do not batch.
        if spec.max_batch > 1 {
            format!(", max batch {} (ActBatch)", spec.max_batch)
        } else {
            String::new()
        },
    );
    Ok(ProbedSpec {
        endpoint: conn.endpoint.uri.clone(),
        protocol_version: spec.protocol_version,
        max_concurrency: checked.max_concurrency,
        name: spec.name,
        observation_history: spec.observation_history,
        actions_executed_per_chunk: spec.actions_executed_per_chunk,
        privileged_observations: spec.privileged_observations,
        summary,
        key_map: None,
    })
}
