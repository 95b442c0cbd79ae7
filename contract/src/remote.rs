//! A participant's endpoint, whatever its wire: [`Remote`] picks the transport by the URL's
//! scheme (`http[s]://` gRPC, `ws[s]://` openpi) and is the one [`Policy`] the workers and local
//! `eval` drive, so the episode code, its deadlines, chunk rules and scoring never ask which
//! wire a policy speaks.
//!
//! Batched decisions (ActBatch, several episodes' decisions in one request) live below this
//! interface: a gRPC [`RemotePolicy`] whose policy declared `max_batch` hands its Acts to the
//! endpoint's shared batcher (`batch.rs`), so the episode code still sees one policy per
//! episode. openpi's protocol has no batch call.

use crate::endpoint::Transport;
use crate::openpi::OpenpiPolicy;
use crate::{Credentials, RemoteConfig, RemoteError, RemotePolicy, SimCamera};
use kitchen_r_episode::policy::{ACTION_DIM, Policy, PolicyError, PolicyInput, PolicySpec};

#[derive(Debug)]
pub enum Remote {
    Grpc(RemotePolicy),
    Openpi(OpenpiPolicy),
}

impl Remote {
    /// Connect to `endpoint` over the wire its scheme names. `key_map` (JSON, empty for the
    /// convention) configures an openpi endpoint; a gRPC endpoint takes none.
    pub fn connect(
        endpoint: &str,
        creds: &Credentials,
        cfg: &RemoteConfig,
        cameras: &[SimCamera],
        key_map: &str,
    ) -> Result<Remote, RemoteError> {
        match Transport::of(endpoint) {
            Some(Transport::Openpi) => {
                OpenpiPolicy::connect(endpoint, creds, cfg, cameras, key_map).map(Remote::Openpi)
            }
            _ if !key_map.trim().is_empty() => Err(RemoteError::Handshake {
                endpoint: endpoint.to_string(),
                reason: "a key map applies to ws:// and wss:// (openpi) endpoints only".into(),
            }),
            _ => RemotePolicy::connect(endpoint, creds, cfg, cameras).map(Remote::Grpc),
        }
    }

    /// The scene id a gRPC policy's Resets announce; openpi has no reset.
    pub fn set_scene(&mut self, scene: &str) {
        if let Remote::Grpc(p) = self {
            p.set_scene(scene);
        }
    }

    /// The policy's self-declared name (gRPC), or the openpi handshake's summary.
    pub fn describe(&self) -> String {
        match self {
            Remote::Grpc(p) if p.batched() => format!(
                "{:?} (decisions batched: ActBatch of up to {})",
                p.wire_spec().name,
                p.wire_spec().max_batch
            ),
            Remote::Grpc(p) => format!("{:?}", p.wire_spec().name),
            Remote::Openpi(p) => p.summary().to_string(),
        }
    }

    fn policy(&mut self) -> &mut dyn Policy {
        match self {
            Remote::Grpc(p) => p,
            Remote::Openpi(p) => p,
        }
    }
}

impl Policy for Remote {
    fn spec(&self) -> &PolicySpec {
        match self {
            Remote::Grpc(p) => p.spec(),
            Remote::Openpi(p) => p.spec(),
        }
    }
    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        self.policy().reset(episode_id, task_index, sub_task)
    }
    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        self.policy().act(input)
    }
}
