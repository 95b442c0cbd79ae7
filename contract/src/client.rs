//! [`RemotePolicy`]: a participant's gRPC endpoint as the sync [`Policy`] the episode runner
//! drives from a plain thread. It owns a small current-thread tokio runtime and blocks on each
//! call, so the runner stays free of async and one simulator thread owns one connection.
//!
//! Set-up ([`RemotePolicy::connect`]) checks the address, waits for `grpc.health.v1` SERVING
//! under the startup deadline and validates the GetSpec handshake; after that every failure is
//! a [`PolicyError`] that fails the current task with its reason.

use kitchen_r_proto::POLICY_PROTOCOL_VERSION;
use kitchen_r_proto::policy::v1 as pb;

use crate::batch::{self, Attachment};
use crate::conn::Conn;
use crate::convert::{self, CameraPlan};
use crate::{Credentials, RemoteConfig, RemoteError, SimCamera, endpoint};
use kitchen_r_episode::policy::{
    ACTION_DIM, HORIZON, MAX_OBSERVATION_HISTORY, Policy, PolicyError, PolicyInput, PolicySpec,
};

pub struct RemotePolicy {
    rt: tokio::runtime::Runtime,
    conn: Conn,
    spec: PolicySpec,
    wire_spec: pb::PolicySpec,
    cameras: Vec<CameraPlan>,
    scene: String,
    /// The endpoint's shared batcher when the policy declared `max_batch` > 1 (and this side
    /// batches): Acts then go through it as ActBatch calls; everything else is unchanged.
    batch: Option<Attachment>,
    call_deadline: std::time::Duration,
}

impl std::fmt::Debug for RemotePolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemotePolicy")
            .field("endpoint", &self.conn.endpoint.uri)
            .field("spec", &self.spec)
            .finish_non_exhaustive()
    }
}

impl RemotePolicy {
    /// Check `endpoint` against the allowed networks, wait until it reports SERVING, and
    /// validate its GetSpec answer against this worker's protocol and `cameras`.
    pub fn connect(
        endpoint: &str,
        creds: &Credentials,
        cfg: &RemoteConfig,
        cameras: &[SimCamera],
    ) -> Result<RemotePolicy, RemoteError> {
        let ep = endpoint::resolve(endpoint, &cfg.allowed_networks)?;
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .map_err(|e| RemoteError::Runtime(e.to_string()))?;
        // The lazy channel spawns its connection task on the runtime it is created in.
        let mut conn = {
            let _guard = rt.enter();
            Conn::new(ep, creds, cfg)?
        };
        let wire_spec = rt.block_on(async {
            conn.wait_serving(cfg.startup_deadline()).await?;
            conn.get_spec(cfg).await
        })?;
        let (spec, cameras) =
            check_spec(&wire_spec, cameras, cfg).map_err(|reason| RemoteError::Handshake {
                endpoint: conn.endpoint.uri.clone(),
                reason,
            })?;
        let batch = batch::batch_size(&wire_spec, cfg)
            .and_then(|n| batch::attach(&conn.endpoint, creds, cfg, &wire_spec, n));
        Ok(RemotePolicy {
            rt,
            conn,
            spec,
            wire_spec,
            cameras,
            scene: String::new(),
            batch,
            call_deadline: cfg.call_deadline(),
        })
    }

    /// The policy's GetSpec answer as received.
    pub fn wire_spec(&self) -> &pb::PolicySpec {
        &self.wire_spec
    }

    /// Whether this policy's decisions go out as ActBatch calls.
    pub fn batched(&self) -> bool {
        self.batch.is_some()
    }

    /// The scene id announced in the following Resets (the runner's `reset` does not carry it).
    pub fn set_scene(&mut self, scene: &str) {
        self.scene = scene.to_string();
    }
}

/// The handshake rules: same protocol version, horizon 16, 10 values per action, cameras the
/// simulator has at a supported resolution and encoding, and (v1.1) an observation history in
/// 1..=8 and an execution count between the organiser's minimum (`cfg`) and the horizon.
pub(crate) fn check_spec(
    spec: &pb::PolicySpec,
    cameras: &[SimCamera],
    cfg: &RemoteConfig,
) -> Result<(PolicySpec, Vec<CameraPlan>), String> {
    if spec.protocol_version != POLICY_PROTOCOL_VERSION {
        return Err(format!(
            "the policy speaks protocol version {}, this worker speaks {POLICY_PROTOCOL_VERSION}",
            spec.protocol_version
        ));
    }
    if spec.horizon as usize != HORIZON {
        return Err(format!("horizon is {}, must be {HORIZON}", spec.horizon));
    }
    if spec.action_dim as usize != ACTION_DIM {
        return Err(format!("action_dim is {}, must be {ACTION_DIM}", spec.action_dim));
    }
    let plans = convert::plan_cameras(spec, cameras)?;
    let (history, execute) = check_v1_1(spec, cfg)?;
    Ok((
        PolicySpec {
            name: spec.name.clone(),
            horizon: HORIZON,
            action_dim: ACTION_DIM,
            cameras: plans.iter().map(|c| c.name.clone()).collect(),
            max_concurrency: spec.max_concurrency.max(1),
            observation_history: history,
            actions_executed_per_chunk: execute,
            privileged_observations: spec.privileged_observations,
        },
        plans,
    ))
}

/// `observation_history` (0 = 1) and `actions_executed_per_chunk` (0 = the organiser's) within
/// their ranges; the reason names the field and the range.
pub(crate) fn check_v1_1(
    spec: &pb::PolicySpec,
    cfg: &RemoteConfig,
) -> Result<(usize, Option<usize>), String> {
    let history = spec.observation_history.max(1) as usize;
    if history > MAX_OBSERVATION_HISTORY {
        return Err(format!(
            "observation_history is {history}, must be between 1 and {MAX_OBSERVATION_HISTORY} (0 means 1)"
        ));
    }
    let min = cfg.min_actions_executed_per_chunk.clamp(1, HORIZON as u32);
    let execute = match spec.actions_executed_per_chunk {
        0 => None,
        n if (min..=HORIZON as u32).contains(&n) => Some(n as usize),
        n => {
            return Err(format!(
                "actions_executed_per_chunk is {n}, must be between {min} (this organiser's \
                 minimum) and {HORIZON}, or 0 for the organiser's default {}",
                cfg.actions_executed_per_chunk
            ));
        }
    };
    Ok((history, execute))
}

impl Policy for RemotePolicy {
    fn spec(&self) -> &PolicySpec {
        &self.spec
    }

    fn reset(&mut self, episode_id: &str, task_index: usize, sub_task: &str) -> Result<(), PolicyError> {
        let req = pb::ResetRequest {
            episode_id: episode_id.to_string(),
            task_index: task_index as u32,
            sub_task: sub_task.to_string(),
            scene_id: self.scene.clone(),
        };
        self.rt.block_on(self.conn.reset(req))
    }

    fn act(&mut self, input: &PolicyInput<'_>) -> Result<Vec<[f64; ACTION_DIM]>, PolicyError> {
        let obs = convert::observation(input, &self.cameras, self.spec.observation_history)?;
        let chunk = match &self.batch {
            Some(b) => b.act(obs, self.call_deadline)?,
            None => self.rt.block_on(self.conn.act(obs))?,
        };
        convert::chunk_from_wire(&chunk, self.spec.horizon)
    }
}
