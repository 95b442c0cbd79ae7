//! openpi WebSocket endpoints (`ws://`, `wss://`): a policy served by openpi's
//! `WebsocketPolicyServer` (PyPI `openpi-server` 0.1.0, `openpi-client` 0.1.2) as the same sync
//! [`Policy`] the episode runner drives for gRPC endpoints. Deadlines, chunk checks, what the
//! endpoint may see and every score stay where they are for gRPC; this module only speaks the
//! other wire:
//!
//! - `GET /healthz` answers 200 (health, under the startup deadline);
//! - on connect the server sends its metadata, a msgpack map;
//! - each decision is one binary message, the observation as the [`KeyMap`] names it
//!   (msgpack-numpy: [`mod@wire`]), answered by one binary message whose actions are an `(H, 10)`
//!   array, H ≥ 16 (the first 16 are the chunk; other keys are ignored);
//! - openpi has no reset: a task's start is seen only as a new `prompt`.
//!
//! One connection per episode. A call that fails (late, closed, text, garbage) fails the
//! current task with its reason and drops the connection; the next decision connects again, so
//! a late answer can never be taken for the next decision's.

mod conn;
mod keys;
mod wire;

use conn::{Target, WsConn};
pub use keys::KeyMap;
pub(crate) use wire::camera_plans;

use crate::endpoint::{self, Endpoint, Transport};
use crate::{Credentials, RemoteConfig, RemoteError, SimCamera};
use kitchen_r_episode::policy::{ACTION_DIM, HORIZON, Policy, PolicyError, PolicyInput, PolicySpec};

/// A checked openpi endpoint with its open connection: what set-up and the probes share.
pub(crate) struct Handshake {
    target: Target,
    conn: WsConn,
    keys: KeyMap,
}

impl Handshake {
    /// The endpoint as checked, `ws[s]://host:port`.
    pub(crate) fn uri(&self) -> &str {
        &self.target.endpoint.uri
    }

    /// One line for the participant: metadata, what is sent and read.
    pub(crate) fn summary(&self, cfg: &RemoteConfig) -> String {
        format!(
            "openpi policy at {}: metadata keys {:?}; {}",
            self.uri(),
            self.conn.metadata,
            self.keys.describe(cfg)
        )
    }

    pub(crate) fn keys(&self) -> &KeyMap {
        &self.keys
    }

    /// Close the connection (the probes are done with it).
    pub(crate) async fn close(self) {
        self.conn.close().await;
    }
}

/// Check the key map, wait for `/healthz` under the startup deadline, connect and read the
/// metadata. `ep` must be an openpi endpoint.
pub(crate) async fn handshake(
    ep: Endpoint,
    creds: &Credentials,
    cfg: &RemoteConfig,
    sim: &[SimCamera],
    key_map: &str,
) -> Result<Handshake, RemoteError> {
    let uri = ep.uri.clone();
    let refuse = |reason: String| RemoteError::Handshake {
        endpoint: uri.clone(),
        reason,
    };
    let keys = KeyMap::parse(key_map).map_err(refuse)?;
    keys.check(sim, cfg).map_err(refuse)?;
    let target = Target::new(ep, creds, cfg);
    target.wait_healthy(cfg.startup_deadline()).await?;
    let conn = target.open(cfg.startup_deadline()).await.map_err(refuse)?;
    Ok(Handshake { target, conn, keys })
}

/// One decision over an open connection: pack, send, wait, unpack (not yet checked by
/// `check_chunk`: the runner and the probe do that).
async fn decide(
    conn: &mut WsConn,
    target: &Target,
    keys: &KeyMap,
    input: &PolicyInput<'_>,
) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
    let plans = wire::camera_plans(keys);
    let request = wire::pack_observation(input, keys, &plans)?;
    let reply = conn.act(target, request).await?;
    wire::unpack_actions(&reply, &keys.actions)
}

impl Handshake {
    /// One decision (the probes' Acts).
    pub(crate) async fn act(
        &mut self,
        input: &PolicyInput<'_>,
    ) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        decide(&mut self.conn, &self.target, &self.keys, input).await
    }
}

/// An openpi endpoint as the runner's [`Policy`]: it owns a current-thread runtime and blocks
/// on each call, as the gRPC client does.
pub struct OpenpiPolicy {
    rt: tokio::runtime::Runtime,
    target: Target,
    conn: Option<WsConn>,
    keys: KeyMap,
    spec: PolicySpec,
    summary: String,
}

impl std::fmt::Debug for OpenpiPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OpenpiPolicy")
            .field("endpoint", &self.target.endpoint.uri)
            .field("keys", &self.keys)
            .finish_non_exhaustive()
    }
}

impl OpenpiPolicy {
    /// Check `endpoint` against the allowed networks and `key_map` (JSON, empty for the
    /// convention) against the simulator's cameras, wait for `/healthz`, connect and read the
    /// metadata.
    pub fn connect(
        endpoint: &str,
        creds: &Credentials,
        cfg: &RemoteConfig,
        cameras: &[SimCamera],
        key_map: &str,
    ) -> Result<OpenpiPolicy, RemoteError> {
        let ep = endpoint::resolve(endpoint, &cfg.allowed_networks)?;
        if ep.transport != Transport::Openpi {
            return Err(RemoteError::Handshake {
                endpoint: ep.uri,
                reason: "not a ws:// or wss:// endpoint".into(),
            });
        }
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| RemoteError::Runtime(e.to_string()))?;
        let h = rt.block_on(handshake(ep, creds, cfg, cameras, key_map))?;
        let summary = h.summary(cfg);
        let spec = PolicySpec {
            name: format!("openpi {}", h.uri()),
            horizon: HORIZON,
            action_dim: ACTION_DIM,
            cameras: h.keys.cameras.keys().cloned().collect(),
            max_concurrency: h.keys.max_concurrency,
            observation_history: 1,
            actions_executed_per_chunk: h.keys.actions_executed_per_chunk.map(|n| n as usize),
            privileged_observations: false,
        };
        Ok(OpenpiPolicy {
            rt,
            target: h.target,
            conn: Some(h.conn),
            keys: h.keys,
            spec,
            summary,
        })
    }

    /// The handshake's one-line summary.
    pub fn summary(&self) -> &str {
        &self.summary
    }
}

impl Policy for OpenpiPolicy {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }

    /// openpi has no reset: the new task shows in the next observation's prompt.
    fn reset(&mut self, _: &str, _: usize, _: &str) -> Result<(), PolicyError> {
        Ok(())
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let (target, keys) = (&self.target, &self.keys);
        let conn = self.conn.take();
        let (conn, answer) = self.rt.block_on(async {
            let mut conn = match conn {
                Some(c) => c,
                // The last call failed: a new connection, under the call deadline (a server that
                // does not answer in time counts as a timeout, towards the successive-timeout
                // abort, as a late answer does).
                None => match tokio::time::timeout(target.call_deadline, target.open_now()).await {
                    Ok(Ok(c)) => c,
                    Ok(Err(e)) => {
                        let why = format!("openpi endpoint {}: reconnecting: {e}", target.endpoint.uri);
                        return (None, Err(PolicyError::Call(why)));
                    }
                    Err(_) => {
                        return (
                            None,
                            Err(PolicyError::Timeout(target.call_deadline.as_secs_f64())),
                        );
                    }
                },
            };
            match decide(&mut conn, target, keys, input).await {
                Ok(chunk) => (Some(conn), Ok(chunk)),
                // A reply that is unusable but complete leaves the stream in step.
                Err(e @ PolicyError::BadChunk(_)) => (Some(conn), Err(e)),
                Err(e) => {
                    conn.close().await;
                    (None, Err(e))
                }
            }
        });
        self.conn = conn;
        answer
    }
}
