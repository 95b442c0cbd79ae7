//! The policy transport: a participant's endpoint seen as a
//! [`Policy`](kitchen_r_episode::policy::Policy) the episode runner drives ([`Remote`]), whether
//! it serves `kitchen_r.policy.v1.Policy` over gRPC ([`client::RemotePolicy`]) or openpi's
//! WebSocket protocol ([`openpi`]); any in-process policy served over the gRPC contract
//! ([`server::serve_policy`], behind `kitchen-r policy oracle`), and the conformance probe behind
//! `kitchen-r check-policy` ([`check`]).
//!
//! Endpoints are untrusted: the address is checked before the first packet ([`AllowedNetworks`]),
//! every call has a deadline, answers are size-capped, and every failure becomes a task failure
//! with a reason rather than a worker error.
//!
//! This crate owns the wire side of the policy contract only. It must not score anything (a
//! failed call is reported as a [`PolicyError`](kitchen_r_episode::policy::PolicyError), the
//! episode crate decides what it costs), lease jobs, or touch a database.

mod batch;
pub mod bench;
pub mod check;
mod client;
mod conn;
mod convert;
mod endpoint;
pub mod openpi;
pub mod probe;
mod remote;
pub mod server;

use std::time::Duration;

use serde::{Deserialize, Serialize};

pub use batch::{BatchStats, batch_stats};
pub use client::RemotePolicy;
pub use endpoint::{AllowedNetworks, EndpointError, Transport};
pub use openpi::{KeyMap, OpenpiPolicy};
pub use remote::Remote;

/// Organiser-side limits of the policy transport (config section `[policy]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RemoteConfig {
    /// How long a freshly registered endpoint may take to accept connections, report SERVING
    /// and answer GetSpec, seconds.
    pub startup_deadline_s: f64,
    /// Deadline of one Reset or Act call, seconds; a late answer is a timeout.
    pub call_deadline_s: f64,
    /// Largest answer accepted from a policy, bytes. A 16×10 chunk is under 2 KB; a bigger
    /// answer fails the task instead of growing the worker's memory.
    pub max_answer_bytes: usize,
    /// Largest observation sent, bytes (two 1024×1024 RGB-D cameras fit).
    pub max_request_bytes: usize,
    /// Actions of each chunk executed before asking again, announced in GetSpec: the default
    /// for a policy that does not choose its own (contract v1.1).
    pub actions_executed_per_chunk: u32,
    /// The smallest execution count a policy may choose in GetSpec (the largest is the
    /// horizon); announced in GetSpec.
    pub min_actions_executed_per_chunk: u32,
    /// Control rate announced in GetSpec, Hz.
    pub control_rate_hz: f64,
    /// Address ranges a policy endpoint may resolve to (`[policy.allowed_networks]`).
    pub allowed_networks: AllowedNetworks,
    /// Batched decisions: the most decisions one ActBatch call carries from this side; the
    /// policy's GetSpec `max_batch` caps it further. 0 or 1 turns batching off (every decision
    /// its own Act, whatever the policy declares).
    pub max_batch: u32,
    /// Batched decisions: the gather window, milliseconds. The first pending decision waits at
    /// most this long for the other episodes' before a partial batch goes out; a batch goes
    /// at once when it is full or when every episode attached to the endpoint is waiting.
    pub batch_gather_ms: f64,
    /// Whether this run may give privileged observations (the server's
    /// `control.privileged_track`, or the job's grant), announced in GetSpec as
    /// `privileged_track`. Not a `[policy]` key: the caller sets it.
    #[serde(skip)]
    pub privileged_track: bool,
}

impl Default for RemoteConfig {
    fn default() -> Self {
        RemoteConfig {
            startup_deadline_s: 30.0,
            call_deadline_s: 10.0,
            max_answer_bytes: 1 << 20,
            max_request_bytes: 32 << 20,
            actions_executed_per_chunk: 8,
            min_actions_executed_per_chunk: 1,
            control_rate_hz: 10.0,
            allowed_networks: AllowedNetworks::default(),
            max_batch: 64,
            batch_gather_ms: 2.0,
            privileged_track: false,
        }
    }
}

impl RemoteConfig {
    pub(crate) fn call_deadline(&self) -> Duration {
        Duration::from_secs_f64(self.call_deadline_s.max(0.001))
    }
    pub fn startup_deadline(&self) -> Duration {
        Duration::from_secs_f64(self.startup_deadline_s.max(0.001))
    }
    pub(crate) fn batch_gather(&self) -> Duration {
        Duration::try_from_secs_f64(self.batch_gather_ms.max(0.0) / 1e3).unwrap_or(Duration::from_secs(1))
    }
}

/// What the participant gave with the endpoint.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Credentials {
    /// Sent as `authorization: Bearer <token>` on every call.
    pub token: Option<String>,
    /// PEM of the CA that signed the endpoint's certificate, for `https://` endpoints with a
    /// private CA; the public web roots are trusted either way.
    pub ca_pem: Option<Vec<u8>>,
}

/// A camera the simulator renders (name and native resolution), from `configs/sensors.toml`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SimCamera {
    pub name: String,
    pub width: u32,
    pub height: u32,
}

impl SimCamera {
    pub fn from_sensors(s: &kitchen_r_sim::SensorsConfig) -> Vec<SimCamera> {
        s.cameras
            .iter()
            .map(|c| SimCamera {
                name: c.name.clone(),
                width: c.width,
                height: c.height,
            })
            .collect()
    }
}

/// Why a remote policy could not be set up (before any episode); registration shows it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RemoteError {
    #[error(transparent)]
    Endpoint(#[from] EndpointError),
    #[error("cannot reach the policy at {endpoint} within {waited_s:.1} s: {reason}")]
    Unreachable {
        endpoint: String,
        waited_s: f64,
        reason: String,
    },
    #[error("health check of {endpoint}: {reason}")]
    Health { endpoint: String, reason: String },
    #[error("GetSpec handshake with {endpoint}: {reason}")]
    Handshake { endpoint: String, reason: String },
    #[error("TLS set-up for {endpoint}: {reason}")]
    Tls { endpoint: String, reason: String },
    #[error("could not start the client runtime: {0}")]
    Runtime(String),
}
